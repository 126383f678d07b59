// Unit tests of the launch file parser: every action, key and substitution, and every error with
// its file:line:column.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "probeless/launch/launch.h"
#include "substitution.h"

namespace probeless::launch {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::StartsWith;
using Strings = std::vector<std::string>;

class LaunchParserTest : public ::testing::Test {
 protected:
  void SetUp() override {
    char pattern[] = "/tmp/launch_parser_test.XXXXXX";
    ASSERT_NE(::mkdtemp(pattern), nullptr);
    dir_ = pattern;
    fs::create_directories(dir_ + "/bin");
    fs::create_directories(dir_ + "/path");
    MakeExecutable("bin/talker");
    MakeExecutable("bin/listener");
    MakeExecutable("path/from_path");
    options_.bin_dir = dir_ + "/bin";
    env_["PATH"] = dir_ + "/path:/usr/bin:/bin";
    options_.get_env = [this](const std::string& name) -> std::optional<std::string> {
      auto it = env_.find(name);
      if (it == env_.end()) return std::nullopt;
      return it->second;
    };
  }
  void TearDown() override { fs::remove_all(dir_); }

  void MakeExecutable(const std::string& relative) {
    const std::string path = dir_ + "/" + relative;
    fs::create_directories(fs::path(path).parent_path());
    std::ofstream(path) << "#!/bin/sh\nexit 0\n";
    ::chmod(path.c_str(), 0755);
  }

  std::string Write(const std::string& name, const std::string& text) {
    const std::string path = dir_ + "/" + name;
    fs::create_directories(fs::path(path).parent_path());
    std::ofstream(path) << text;
    return path;
  }

  LaunchDescription Load(const std::string& name, const std::string& text) {
    return LoadLaunchFile(Write(name, text), options_);
  }

  // The LaunchError message of loading `text` as `name`; fails the test if none is thrown.
  std::string Error(const std::string& name, const std::string& text) {
    try {
      Load(name, text);
    } catch (const LaunchError& e) {
      return e.what();
    } catch (const std::exception& e) {
      ADD_FAILURE() << "not a LaunchError: " << e.what();
      return "";
    }
    ADD_FAILURE() << "no error for:\n" << text;
    return "";
  }

  // "<dir>/<name>:<line>:<column>: "
  std::string At(const std::string& name, int line, int column) {
    return dir_ + "/" + name + ":" + std::to_string(line) + ":" + std::to_string(column) + ": ";
  }

  std::string dir_;
  std::map<std::string, std::string> env_;
  ParseOptions options_;
};

// --- nodes ---

TEST_F(LaunchParserTest, MinimalNodeFollowsTheCommandLineContract) {
  const auto d = Load("a.yaml", "launch:\n- node: {exec: talker}\n");
  ASSERT_EQ(d.nodes.size(), 1u);
  const NodeSpec& n = d.nodes[0];
  EXPECT_EQ(n.name, "talker");
  EXPECT_EQ(n.node_namespace, "/");
  EXPECT_EQ(n.fully_qualified_name, "/talker");
  EXPECT_EQ(n.executable, dir_ + "/bin/talker");
  EXPECT_EQ(n.argv,
            (Strings{dir_ + "/bin/talker", "--ros-args", "-r", "__node:=talker", "-r", "__ns:=/"}));
  ASSERT_EQ(n.environment.size(), 1u);
  EXPECT_EQ(n.environment[0],
            (std::pair<std::string, std::string>("PROBELESS_NODE_NAME", "/talker")));
  EXPECT_EQ(n.output, OutputMode::kScreen);
  EXPECT_FALSE(n.respawn);
  EXPECT_EQ(n.respawn_max_retries, -1);
  EXPECT_FALSE(n.required);
  EXPECT_TRUE(n.prefix.empty());
  EXPECT_EQ(n.location.file, dir_ + "/a.yaml");
  EXPECT_EQ(n.location.line, 2);
}

TEST_F(LaunchParserTest, FullNodeArgvOrder) {
  Write("params.yaml", "/**:\n  ros__parameters: {a: 1}\n");
  const auto d = Load("a.yaml", R"yaml(launch:
- node:
    pkg: ignored_pkg
    exec: talker
    name: chatter
    namespace: robot
    args: "--rate 10 'two words'"
    param:
    - {name: speed, value: 2.5}
    - {from: params.yaml}
    - {name: label, value: "hello"}
    remap:
    - {from: /chatter, to: /chat}
)yaml");
  ASSERT_EQ(d.nodes.size(), 1u);
  const NodeSpec& n = d.nodes[0];
  EXPECT_EQ(n.fully_qualified_name, "/robot/chatter");
  EXPECT_EQ(n.argv, (Strings{dir_ + "/bin/talker", "--rate", "10", "two words", "--ros-args", "-r",
                             "__node:=chatter", "-r", "__ns:=/robot", "--params-file",
                             dir_ + "/params.yaml", "-p", "speed:=2.5", "-p", "label:='hello'",
                             "-r", "/chatter:=/chat"}));
  EXPECT_EQ(n.argv, BuildNodeArgv(n));
}

TEST_F(LaunchParserTest, DefaultNameIsTheSanitizedExecutableName) {
  MakeExecutable("bin/my-node.py");
  const auto d = Load("a.yaml", "launch:\n- node: {exec: my-node.py}\n");
  EXPECT_EQ(d.nodes.at(0).name, "my_node_py");
}

TEST_F(LaunchParserTest, ExecutableResolutionOrder) {
  // bin_dir wins over a file next to the launch file, which wins over PATH.
  MakeExecutable("talker");
  MakeExecutable("local_only");
  MakeExecutable("tools/sub_exec");
  const auto d = Load("a.yaml", R"yaml(launch:
- node: {exec: talker, name: a}
- node: {exec: local_only, name: b}
- node: {exec: from_path, name: c}
- node: {exec: tools/sub_exec, name: d}
- node: {exec: sh, name: e}
)yaml");
  ASSERT_EQ(d.nodes.size(), 5u);
  EXPECT_EQ(d.nodes[0].executable, dir_ + "/bin/talker");
  EXPECT_EQ(d.nodes[1].executable, dir_ + "/local_only");
  EXPECT_EQ(d.nodes[2].executable, dir_ + "/path/from_path");
  EXPECT_EQ(d.nodes[3].executable, dir_ + "/tools/sub_exec");
  EXPECT_EQ(d.nodes[4].executable, "/usr/bin/sh");
}

TEST_F(LaunchParserTest, AbsoluteExecutable) {
  const auto d = Load("a.yaml", "launch:\n- node: {exec: /bin/sh}\n");
  EXPECT_EQ(d.nodes.at(0).executable, "/bin/sh");
  EXPECT_EQ(d.nodes.at(0).name, "sh");
}

TEST_F(LaunchParserTest, ExecutableNotFoundNamesNodeAndExec) {
  const std::string error =
      Error("a.yaml", "launch:\n- node: {exec: talker}\n- node:\n    name: lost\n    exec: nope\n");
  EXPECT_THAT(error, StartsWith(At("a.yaml", 5, 11)));
  EXPECT_THAT(error, HasSubstr("node 'lost': executable 'nope' not found"));
}

TEST_F(LaunchParserTest, NonExecutableFileIsNotFound) {
  Write("bin/plain", "data");
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: plain}\n"),
              HasSubstr("executable 'plain' not found"));
}

TEST_F(LaunchParserTest, UnresolvedExecutablesAreKeptWhenResolutionIsOff) {
  options_.resolve_executables = false;
  const auto d = Load("a.yaml", "launch:\n- node: {exec: nope, launch-prefix: no_such_gdb -x}\n");
  EXPECT_EQ(d.nodes.at(0).executable, "nope");
  EXPECT_EQ(d.nodes.at(0).prefix, (Strings{"no_such_gdb", "-x"}));
}

TEST_F(LaunchParserTest, ParameterValueTexts) {
  const auto d = Load("a.yaml", R"yaml(launch:
- arg: {name: rate, default: "15"}
- arg: {name: none, default: ""}
- node:
    exec: talker
    param:
    - {name: int, value: 10}
    - {name: quoted_int, value: "10"}
    - {name: single, value: 'it''s'}
    - {name: flag, value: true}
    - {name: list, value: [1, "two", 3.5]}
    - {name: substituted, value: "$(arg rate)"}
    - {name: tagged, value: !!str 5}
    - {name: dotted.name, value: x}
    - {name: substituted_empty, value: "$(arg none)"}
)yaml");
  const auto& p = d.nodes.at(0).parameters;
  ASSERT_EQ(p.size(), 9u);
  EXPECT_EQ(p[0].value, "10");
  EXPECT_EQ(p[1].value, "'10'");
  EXPECT_EQ(p[2].value, "'it''s'");
  EXPECT_EQ(p[3].value, "true");
  EXPECT_EQ(p[4].value, "[1, 'two', 3.5]");
  EXPECT_EQ(p[5].value, "15");
  EXPECT_EQ(p[6].value, "'5'");
  EXPECT_EQ(p[7].name, "dotted.name");
  EXPECT_EQ(p[8].value, "''");  // an empty substitution is the empty string, not "-p name:="
}

TEST_F(LaunchParserTest, ParameterErrors) {
  EXPECT_THAT(Error("a.yaml", "launch:\n- node:\n    exec: talker\n    param: {a: 1}\n"),
              StartsWith(At("a.yaml", 4, 12)));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node:\n    exec: talker\n    param:\n    - {name: x}\n"),
              AllOf(StartsWith(At("a.yaml", 5, 7)), HasSubstr("missing 'value'")));
  EXPECT_THAT(
      Error("a.yaml", "launch:\n- node:\n    exec: talker\n    param:\n    - {name: x, value: }\n"),
      HasSubstr("parameter 'x' has no value"));
  EXPECT_THAT(
      Error("a.yaml",
            "launch:\n- node:\n    exec: talker\n    param:\n    - {name: x, value: {a: 1}}\n"),
      AllOf(StartsWith(At("a.yaml", 5, 24)), HasSubstr("expected a scalar or a list")));
  EXPECT_THAT(
      Error("a.yaml",
            "launch:\n- node:\n    exec: talker\n    param:\n    - {name: 'a b', value: 1}\n"),
      AllOf(StartsWith(At("a.yaml", 5, 14)), HasSubstr("invalid parameter name 'a b'")));
  EXPECT_THAT(
      Error("a.yaml", "launch:\n- node:\n    exec: talker\n    param:\n    - {from: none.yaml}\n"),
      AllOf(StartsWith(At("a.yaml", 5, 14)),
            HasSubstr("parameter file '" + dir_ + "/none.yaml' not found")));
  Write("p.yaml", "{}");
  EXPECT_THAT(
      Error("a.yaml",
            "launch:\n- node:\n    exec: talker\n    param:\n    - {from: p.yaml, name: x}\n"),
      AllOf(StartsWith(At("a.yaml", 5, 7)), HasSubstr("either 'from' or 'name'")));
}

TEST_F(LaunchParserTest, RemapsAndErrors) {
  const auto d = Load("a.yaml",
                      "launch:\n- node:\n    exec: talker\n    remap:\n    - {from: a, to: b}\n"
                      "    - {from: /c, to: /d/e}\n");
  ASSERT_EQ(d.nodes.at(0).remaps.size(), 2u);
  EXPECT_EQ(d.nodes[0].remaps[1].from, "/c");
  EXPECT_EQ(d.nodes[0].remaps[1].to, "/d/e");
  EXPECT_THAT(Error("a.yaml", "launch:\n- node:\n    exec: talker\n    remap:\n    - {from: a}\n"),
              AllOf(StartsWith(At("a.yaml", 5, 7)), HasSubstr("'remap' is missing 'to'")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node:\n    exec: talker\n    remap: x\n"),
              AllOf(StartsWith(At("a.yaml", 4, 12)), HasSubstr("'remap' must be a list")));
  EXPECT_THAT(
      Error("a.yaml", "launch:\n- node:\n    exec: talker\n    remap:\n    - {from: '', to: b}\n"),
      HasSubstr("empty remap name"));
}

TEST_F(LaunchParserTest, NodeEnvironment) {
  const auto d = Load("a.yaml", R"yaml(launch:
- set_env: {name: SHARED, value: one}
- node:
    exec: talker
    env:
    - {name: OWN, value: "x y"}
    - {name: SHARED, value: two}
)yaml");
  using Env = std::vector<std::pair<std::string, std::string>>;
  EXPECT_EQ(d.nodes.at(0).environment, (Env{{"SHARED", "one"},
                                            {"OWN", "x y"},
                                            {"SHARED", "two"},
                                            {"PROBELESS_NODE_NAME", "/talker"}}));
  EXPECT_THAT(
      Error("a.yaml",
            "launch:\n- node:\n    exec: talker\n    env:\n    - {name: 'A=B', value: x}\n"),
      AllOf(StartsWith(At("a.yaml", 5, 14)), HasSubstr("invalid environment variable")));
}

TEST_F(LaunchParserTest, OutputModes) {
  const auto d = Load("a.yaml", R"yaml(launch:
- node: {exec: talker, name: a, output: screen}
- node: {exec: talker, name: b, output: log}
- node: {exec: talker, name: c, output: both}
)yaml");
  EXPECT_EQ(d.nodes.at(0).output, OutputMode::kScreen);
  EXPECT_EQ(d.nodes.at(1).output, OutputMode::kLog);
  EXPECT_EQ(d.nodes.at(2).output, OutputMode::kLog);
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, output: file}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 32)), HasSubstr("invalid output 'file'")));
}

TEST_F(LaunchParserTest, RespawnAndRequired) {
  const auto d = Load("a.yaml", R"yaml(launch:
- node: {exec: talker, name: a, respawn: "true", respawn_delay: 0.25, respawn_max_retries: 3}
- node: {exec: talker, name: b, respawn: 1, required: True}
- node: {exec: talker, name: c, on_exit: shutdown, respawn: 0}
- node: {exec: talker, name: d, respawn: FALSE, required: "0"}
)yaml");
  EXPECT_TRUE(d.nodes.at(0).respawn);
  EXPECT_DOUBLE_EQ(d.nodes.at(0).respawn_delay_s, 0.25);
  EXPECT_EQ(d.nodes.at(0).respawn_max_retries, 3);
  EXPECT_FALSE(d.nodes.at(0).required);
  EXPECT_TRUE(d.nodes.at(1).respawn);
  EXPECT_EQ(d.nodes.at(1).respawn_max_retries, -1);
  EXPECT_TRUE(d.nodes.at(1).required);
  EXPECT_TRUE(d.nodes.at(2).required);
  EXPECT_FALSE(d.nodes.at(2).respawn);
  EXPECT_FALSE(d.nodes.at(3).respawn);
  EXPECT_FALSE(d.nodes.at(3).required);
}

TEST_F(LaunchParserTest, RespawnErrors) {
  EXPECT_THAT(
      Error("a.yaml", "launch:\n- node: {exec: talker, respawn: yes}\n"),
      AllOf(StartsWith(At("a.yaml", 2, 33)),
            HasSubstr("invalid boolean 'yes' for 'respawn' (expected true, false, 1 or 0)")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, respawn_delay: -1}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 39)), HasSubstr("invalid respawn_delay '-1'")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, respawn_delay: 1s}\n"),
              HasSubstr("invalid respawn_delay '1s'"));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, respawn_max_retries: 2.5}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 45)), HasSubstr("invalid respawn_max_retries")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, required: maybe}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 34)), HasSubstr("for 'required'")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, on_exit: restart}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 33)), HasSubstr("unsupported on_exit 'restart'")));
}

TEST_F(LaunchParserTest, LaunchPrefix) {
  const auto d = Load("a.yaml", R"yaml(launch:
- node: {exec: talker, name: a, launch-prefix: "env FOO=1"}
- node: {exec: talker, name: b, launch_prefix: "gdb -batch -ex run --args"}
)yaml");
  EXPECT_EQ(d.nodes.at(0).prefix, (Strings{"/usr/bin/env", "FOO=1"}));
  // gdb may not be installed: b's prefix resolution is checked only when present.
  EXPECT_EQ(d.nodes.at(0).argv.at(0), dir_ + "/bin/talker");
}

TEST_F(LaunchParserTest, LaunchPrefixProgramMissing) {
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, launch-prefix: 'nosuchprog -x'}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 39)),
                    HasSubstr("launch-prefix program 'nosuchprog' not found")));
}

TEST_F(LaunchParserTest, ArgsAreSplitLikeAShell) {
  const auto d = Load("a.yaml", R"yaml(launch:
- node:
    exec: talker
    args: "plain 'single quoted' \"double \\\"q\\\"\" back\\ slash '' end"
)yaml");
  EXPECT_EQ(d.nodes.at(0).arguments,
            (Strings{"plain", "single quoted", "double \"q\"", "back slash", "", "end"}));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node:\n    exec: talker\n    args: \"a 'b\"\n"),
              AllOf(StartsWith(At("a.yaml", 4, 11)), HasSubstr("unterminated single quote")));
}

TEST(SplitShellWords, Cases) {
  EXPECT_EQ(SplitShellWords(""), Strings{});
  EXPECT_EQ(SplitShellWords("  a\tb\n c  "), (Strings{"a", "b", "c"}));
  EXPECT_EQ(SplitShellWords("a\"b c\"d"), (Strings{"ab cd"}));
  EXPECT_EQ(SplitShellWords("\"\\n\""), (Strings{"\\n"}));
  EXPECT_THROW(SplitShellWords("\"open"), LaunchError);
}

TEST(ParseArgumentOverride, Cases) {
  EXPECT_EQ(ParseArgumentOverride("a:=b"), (std::pair<std::string, std::string>("a", "b")));
  EXPECT_EQ(ParseArgumentOverride("a:="), (std::pair<std::string, std::string>("a", "")));
  EXPECT_EQ(ParseArgumentOverride("a:=b:=c"), (std::pair<std::string, std::string>("a", "b:=c")));
  EXPECT_FALSE(ParseArgumentOverride("file.yaml"));
  EXPECT_FALSE(ParseArgumentOverride(":=x"));
}

// --- arguments and substitutions ---

TEST_F(LaunchParserTest, ArgDefaultsOverridesAndVar) {
  const std::string text = R"yaml(launch:
- arg: {name: rate, default: "10", description: "rate in Hz"}
- arg: {name: who, default: world}
- node: {exec: talker, args: "--rate $(arg rate) --who $(var who)"}
)yaml";
  auto d = Load("a.yaml", text);
  EXPECT_EQ(d.nodes.at(0).arguments, (Strings{"--rate", "10", "--who", "world"}));
  using Args = std::vector<std::pair<std::string, std::string>>;
  EXPECT_EQ(d.arguments, (Args{{"rate", "10"}, {"who", "world"}}));
  options_.arguments = {{"rate", "50"}};
  d = Load("a.yaml", text);
  EXPECT_EQ(d.nodes.at(0).arguments, (Strings{"--rate", "50", "--who", "world"}));
  EXPECT_EQ(d.arguments, (Args{{"rate", "50"}, {"who", "world"}}));
}

TEST_F(LaunchParserTest, ArgWithoutValue) {
  const std::string text =
      "launch:\n- arg: {name: robot}\n- node: {exec: talker, name: $(arg robot)}\n";
  EXPECT_THAT(Error("a.yaml", text),
              AllOf(StartsWith(At("a.yaml", 2, 8)),
                    HasSubstr("launch argument 'robot' has no value (expected robot:=<value>")));
  options_.arguments = {{"robot", "r2"}};
  EXPECT_EQ(Load("a.yaml", text).nodes.at(0).name, "r2");
}

TEST_F(LaunchParserTest, UnknownArgSubstitution) {
  EXPECT_THAT(Error("a.yaml",
                    "launch:\n- arg: {name: known, default: 1}\n"
                    "- node:\n    exec: talker\n    args: \"x $(arg unknown)\"\n"),
              AllOf(StartsWith(At("a.yaml", 5, 11)),
                    HasSubstr("unknown launch argument 'unknown' in '$(arg unknown)' (expected an "
                              "arg or let declared before use: known)")));
}

TEST_F(LaunchParserTest, UnknownCommandLineArgument) {
  options_.arguments = {{"typo", "1"}};
  EXPECT_THAT(Error("a.yaml", "launch:\n- arg: {name: rate, default: 1}\n"),
              AllOf(StartsWith(At("a.yaml", 1, 1)),
                    HasSubstr("unknown launch argument 'typo' given on the command line (expected "
                              "one of the declared arguments: rate)")));
}

TEST_F(LaunchParserTest, ArgNameErrors) {
  EXPECT_THAT(Error("a.yaml", "launch:\n- arg: {name: 'bad name', default: 1}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 15)), HasSubstr("invalid launch argument name")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- arg: {default: 1}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 8)), HasSubstr("'arg' is missing 'name'")));
  EXPECT_THAT(
      Error("a.yaml", "launch:\n- arg: {name: a, value: 1}\n"),
      AllOf(StartsWith(At("a.yaml", 2, 18)),
            HasSubstr("unknown key 'value' in 'arg' (expected one of: default, description, "
                      "if, name, unless)")));
}

TEST_F(LaunchParserTest, Let) {
  const auto d = Load("a.yaml", R"yaml(launch:
- arg: {name: base, default: robot}
- let: {name: full, value: "$(arg base)_1"}
- let: {name: base, value: changed}
- node: {exec: talker, name: $(var full), namespace: $(arg base)}
)yaml");
  EXPECT_EQ(d.nodes.at(0).fully_qualified_name, "/changed/robot_1");
  EXPECT_THAT(Error("a.yaml", "launch:\n- let: {name: x}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 8)), HasSubstr("'let' is missing 'value'")));
}

TEST_F(LaunchParserTest, EnvSubstitution) {
  env_["PROBE_TEST_VAR"] = "from_env";
  const auto d = Load("a.yaml", R"yaml(launch:
- node: {exec: talker, name: a, args: "$(env PROBE_TEST_VAR) $(env PROBE_UNSET fallback) $(env PROBE_UNSET 'two words')"}
- set_env: {name: PROBE_UNSET, value: now_set}
- node: {exec: talker, name: b, args: "$(env PROBE_UNSET)"}
)yaml");
  EXPECT_EQ(d.nodes.at(0).arguments, (Strings{"from_env", "fallback", "two", "words"}));
  EXPECT_EQ(d.nodes.at(1).arguments, (Strings{"now_set"}));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, args: $(env PROBE_UNSET)}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 30)),
                    HasSubstr("environment variable 'PROBE_UNSET' is not set")));
}

TEST_F(LaunchParserTest, DirnameSubstitution) {
  Write("sub/params.yaml", "{}");
  const auto d = Load("sub/a.yaml", R"yaml(launch:
- node:
    exec: talker
    args: "$(dirname)"
    param: [{from: "$(dirname)/params.yaml"}]
)yaml");
  EXPECT_EQ(d.nodes.at(0).arguments, (Strings{dir_ + "/sub"}));
  EXPECT_EQ(d.nodes.at(0).param_files, (Strings{dir_ + "/sub/params.yaml"}));
}

TEST_F(LaunchParserTest, NestedSubstitutions) {
  env_["ROBOT_1"] = "nested_ok";
  const auto d = Load("a.yaml", R"yaml(launch:
- arg: {name: id, default: "1"}
- node: {exec: talker, args: "$(env ROBOT_$(arg id)) $(env MISSING_$(arg id) 'd $(arg id)')"}
)yaml");
  EXPECT_EQ(d.nodes.at(0).arguments, (Strings{"nested_ok", "d", "1"}));
}

TEST_F(LaunchParserTest, SubstitutionSyntaxErrors) {
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, args: \"$(arg x\"}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 30)),
                    HasSubstr("unterminated substitution '$(arg x' (expected ')')")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, args: \"$(find pkg)\"}\n"),
              HasSubstr("unknown substitution '$(find pkg)' (expected arg, var, env or dirname)"));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, args: \"$(arg)\"}\n"),
              HasSubstr("takes one argument"));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, args: \"$(dirname x)\"}\n"),
              HasSubstr("takes no argument"));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, args: \"$()\"}\n"),
              HasSubstr("empty substitution"));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, args: \"$(env 'X)\"}\n"),
              HasSubstr("unterminated quote"));
  std::string deep = "x";
  for (int i = 0; i < 12; ++i) deep = "$(env X " + deep + ")";
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, args: \"" + deep + "\"}\n"),
              HasSubstr("nested too deeply"));
}

TEST(Substitution, PlainTextIsUnchanged) {
  std::map<std::string, std::string> variables{{"a", "1"}};
  internal::SubstitutionContext context;
  context.variables = &variables;
  context.get_env = [](const std::string&) { return std::nullopt; };
  EXPECT_EQ(internal::Substitute("no $ substitution (here)", context), "no $ substitution (here)");
  EXPECT_EQ(internal::Substitute("$(arg a)$(arg a)", context), "11");
  EXPECT_FALSE(internal::ContainsSubstitution("$ (x)"));
}

// --- conditions ---

TEST_F(LaunchParserTest, IfAndUnless) {
  const auto d = Load("a.yaml", R"yaml(launch:
- arg: {name: on, default: "true"}
- node: {exec: talker, name: a, if: $(arg on)}
- node: {exec: talker, name: b, unless: $(arg on)}
- node: {exec: talker, name: c, if: "0"}
- node: {exec: talker, name: d, if: "1", unless: "false"}
- arg: {name: skipped, if: "false"}
- include: {file: does_not_exist.yaml, if: "false"}
- group: {if: "false", children: [{node: {exec: talker, name: e}}]}
- let: {name: on, value: "false", unless: "true"}
- set_env: {name: SKIPPED, value: x, if: "false"}
- node: {exec: talker, name: f, if: $(arg on), args: $(env SKIPPED none)}
)yaml");
  Strings names;
  for (const auto& n : d.nodes) names.push_back(n.name);
  EXPECT_EQ(names, (Strings{"a", "d", "f"}));
  EXPECT_EQ(d.nodes.at(2).arguments, (Strings{"none"}));
}

TEST_F(LaunchParserTest, BadConditionValue) {
  EXPECT_THAT(Error("a.yaml",
                    "launch:\n- arg: {name: on, default: maybe}\n"
                    "- node:\n    exec: talker\n    if: $(arg on)\n"),
              AllOf(StartsWith(At("a.yaml", 5, 9)),
                    HasSubstr("invalid boolean 'maybe' for 'if' (expected true, false, 1 or 0)")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- group: {unless: 2, children: []}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 19)), HasSubstr("for 'unless'")));
}

// --- groups and namespaces ---

TEST_F(LaunchParserTest, GroupNamespaces) {
  const auto d = Load("a.yaml", R"yaml(launch:
- group:
    namespace: robot
    children:
    - node: {exec: talker, name: a}
    - node: {exec: talker, name: b, namespace: arm}
    - node: {exec: talker, name: c, namespace: /abs}
    - group:
        namespace: /inner/
        children:
        - node: {exec: talker, name: d}
    - push-ros-namespace: {namespace: pushed}
    - node: {exec: talker, name: e}
- node: {exec: talker, name: f}
- group:
    children:
    - push_ros_namespace: scalar_form
    - node: {exec: talker, name: g}
)yaml");
  Strings names;
  for (const auto& n : d.nodes) names.push_back(n.fully_qualified_name);
  EXPECT_EQ(names, (Strings{"/robot/a", "/robot/arm/b", "/abs/c", "/inner/d", "/robot/pushed/e",
                            "/f", "/scalar_form/g"}));
  EXPECT_EQ(d.nodes.at(1).node_namespace, "/robot/arm");
  EXPECT_EQ(d.nodes.at(1).argv.at(5), "__ns:=/robot/arm");
  EXPECT_EQ(d.nodes.at(1).environment.back().second, "/robot/arm/b");
}

TEST_F(LaunchParserTest, GroupScoping) {
  const auto d = Load("a.yaml", R"yaml(launch:
- let: {name: v, value: outer}
- group:
    children:
    - let: {name: v, value: scoped}
    - set_env: {name: E, value: scoped}
    - node: {exec: talker, name: a, args: "$(var v) $(env E unset)"}
- node: {exec: talker, name: b, args: "$(var v) $(env E unset)"}
- group:
    scoped: false
    namespace: ns
    children:
    - let: {name: v, value: leaked}
    - set_env: {name: E, value: leaked}
    - push-ros-namespace: {namespace: more}
- node: {exec: talker, name: c, args: "$(var v) $(env E unset)"}
)yaml");
  EXPECT_EQ(d.nodes.at(0).arguments, (Strings{"scoped", "scoped"}));
  EXPECT_EQ(d.nodes.at(1).arguments, (Strings{"outer", "unset"}));
  EXPECT_EQ(d.nodes.at(2).arguments, (Strings{"leaked", "leaked"}));
  EXPECT_EQ(d.nodes.at(2).node_namespace, "/");  // namespaces never leave a group
  EXPECT_EQ(d.nodes.at(2).environment.front(),
            (std::pair<std::string, std::string>("E", "leaked")));
}

TEST_F(LaunchParserTest, GroupErrors) {
  EXPECT_THAT(Error("a.yaml", "launch:\n- group: {namespace: x}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 10)), HasSubstr("'group' is missing 'children'")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- group: {children: {node: {exec: talker}}}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 21)), HasSubstr("actions must be a list")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- group:\n    namespace: 'bad ns'\n    children: []\n"),
              AllOf(StartsWith(At("a.yaml", 3, 16)), HasSubstr("invalid namespace 'bad ns'")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- group: {scoped: perhaps, children: []}\n"),
              HasSubstr("invalid boolean 'perhaps' for 'scoped'"));
}

TEST_F(LaunchParserTest, SelfReferencingAliasIsBounded) {
  EXPECT_THAT(Error("a.yaml", "launch: &a\n- group: {children: *a}\n"),
              AnyOf(HasSubstr("nested too deeply"), HasSubstr("too many actions")));
}

// --- includes ---

TEST_F(LaunchParserTest, IncludeWithArgs) {
  Write("sub/child.yaml", R"yaml(launch:
- arg: {name: robot, default: default_robot}
- arg: {name: inherited_default, default: child_default}
- let: {name: leaked, value: "no"}
- node: {exec: talker, name: $(arg robot), args: "$(arg parent_only) $(arg inherited_default) $(dirname)"}
)yaml");
  const auto d = Load("a.yaml", R"yaml(launch:
- let: {name: parent_only, value: p}
- let: {name: inherited_default, value: from_parent}
- include:
    file: sub/child.yaml
    arg:
    - {name: robot, value: "r_$(var parent_only)"}
- group:
    namespace: second
    children:
    - include: {file: "$(dirname)/sub/child.yaml"}
- node: {exec: talker, name: last, args: "$(env LEAK unset)"}
)yaml");
  ASSERT_EQ(d.nodes.size(), 3u);
  EXPECT_EQ(d.nodes[0].fully_qualified_name, "/r_p");
  EXPECT_EQ(d.nodes[0].arguments, (Strings{"p", "from_parent", dir_ + "/sub"}));
  EXPECT_EQ(d.nodes[1].fully_qualified_name, "/second/default_robot");
  EXPECT_EQ(d.nodes[0].location.file, dir_ + "/sub/child.yaml");
  EXPECT_EQ(d.nodes[0].location.line, 5);
  // Only top-level arguments are reported.
  EXPECT_TRUE(d.arguments.empty());
}

TEST_F(LaunchParserTest, IncludeScopeDoesNotLeak) {
  Write("child.yaml", "launch:\n- let: {name: secret, value: x}\n");
  EXPECT_THAT(
      Error("a.yaml",
            "launch:\n- include: {file: child.yaml}\n"
            "- node: {exec: talker, args: $(var secret)}\n"),
      AllOf(StartsWith(At("a.yaml", 3, 30)), HasSubstr("unknown launch argument 'secret'")));
}

TEST_F(LaunchParserTest, OverridesReachIncludedArguments) {
  Write("child.yaml",
        "launch:\n- arg: {name: deep, default: d}\n"
        "- node: {exec: talker, args: $(arg deep)}\n");
  options_.arguments = {{"deep", "overridden"}};
  const auto d = Load("a.yaml", "launch:\n- include: {file: child.yaml}\n");
  EXPECT_EQ(d.nodes.at(0).arguments, (Strings{"overridden"}));
}

TEST_F(LaunchParserTest, ErrorsInIncludedFilesNameThatFile) {
  Write("inc/child.yaml", "launch:\n- node:\n    exec: talker\n    colour: red\n");
  EXPECT_THAT(Error("a.yaml", "launch:\n- include: {file: inc/child.yaml}\n"),
              AllOf(StartsWith(dir_ + "/inc/child.yaml:4:5: "),
                    HasSubstr("unknown key 'colour' in 'node'")));
  Write("inc/broken.yaml", "launch:\n- node: {exec: talker\n");
  EXPECT_THAT(Error("a.yaml", "launch:\n- include: {file: inc/broken.yaml}\n"),
              AllOf(StartsWith(dir_ + "/inc/broken.yaml:3:1: "), HasSubstr("YAML syntax error")));
}

TEST_F(LaunchParserTest, IncludeCycle) {
  Write("b.yaml", "launch:\n- node: {exec: talker}\n- include: {file: a.yaml}\n");
  EXPECT_THAT(Error("a.yaml", "launch:\n- include: {file: b.yaml}\n"),
              AllOf(StartsWith(dir_ + "/b.yaml:3:19: "),
                    HasSubstr("include cycle " + dir_ + "/a.yaml -> " + dir_ + "/b.yaml -> " +
                              dir_ + "/a.yaml (expected includes without a cycle)")));
  EXPECT_THAT(Error("self.yaml", "launch:\n- include: {file: ./self.yaml}\n"),
              AllOf(StartsWith(At("self.yaml", 2, 19)), HasSubstr("include cycle")));
}

TEST_F(LaunchParserTest, IncludeMissingFileAndBadArgs) {
  EXPECT_THAT(Error("a.yaml", "launch:\n- include:\n    file: nope.yaml\n"),
              AllOf(StartsWith(At("a.yaml", 3, 11)),
                    HasSubstr("cannot read launch file '" + dir_ + "/nope.yaml'")));
  Write("c.yaml", "launch: []\n");
  EXPECT_THAT(Error("a.yaml", "launch:\n- include: {file: c.yaml, arg: {name: x}}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 32)), HasSubstr("'arg' of include must be a list")));
  EXPECT_THAT(
      Error("a.yaml", "launch:\n- include: {file: c.yaml, arg: [{name: x}]}\n"),
      AllOf(StartsWith(At("a.yaml", 2, 33)), HasSubstr("'include arg' is missing 'value'")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- include: {}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 12)), HasSubstr("'include' is missing 'file'")));
}

TEST_F(LaunchParserTest, MissingTopLevelFile) {
  try {
    LoadLaunchFile(dir_ + "/absent.yaml", options_);
    ADD_FAILURE() << "no error";
  } catch (const LaunchError& e) {
    EXPECT_THAT(e.what(), StartsWith(dir_ + "/absent.yaml:1:1: cannot read launch file"));
  }
}

// --- structural errors ---

TEST_F(LaunchParserTest, YamlSyntaxError) {
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker\n- node: x\n"),
              AllOf(StartsWith(At("a.yaml", 3, 7)), HasSubstr("YAML syntax error: "),
                    HasSubstr("(expected valid YAML)")));
  EXPECT_THAT(Error("a.yaml", "launch:\n\t- node: {}\n"), HasSubstr("YAML syntax error"));
}

TEST_F(LaunchParserTest, TopLevelErrors) {
  EXPECT_THAT(Error("a.yaml", ""), AllOf(StartsWith(At("a.yaml", 1, 1)),
                                         HasSubstr("must be a mapping with a 'launch' list")));
  EXPECT_THAT(Error("a.yaml", "- node: {exec: talker}\n"),
              AllOf(StartsWith(At("a.yaml", 1, 1)), HasSubstr("must be a mapping")));
  EXPECT_THAT(Error("a.yaml", "nodes: []\n"),
              AllOf(StartsWith(At("a.yaml", 1, 1)),
                    HasSubstr("unknown key 'nodes' in 'launch file' (expected one of: launch)")));
  EXPECT_THAT(Error("a.yaml", "launch: {node: {}}\n"),
              AllOf(StartsWith(At("a.yaml", 1, 9)), HasSubstr("actions must be a list")));
  EXPECT_TRUE(Load("a.yaml", "launch:\n").nodes.empty());
}

TEST_F(LaunchParserTest, ActionErrors) {
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker}\n- timer: {period: 1}\n"),
              AllOf(StartsWith(At("a.yaml", 3, 3)),
                    HasSubstr("unknown action 'timer' (expected one of: arg, group, include, let, "
                              "node, push-ros-namespace, set_env)")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker}\n  arg: {name: x}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 3)), HasSubstr("exactly one key")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- just a string\n"),
              AllOf(StartsWith(At("a.yaml", 2, 3)), HasSubstr("exactly one key")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node:\n"),
              AllOf(StartsWith(At("a.yaml", 2, 3)), HasSubstr("'node' must be a mapping")));
}

TEST_F(LaunchParserTest, NodeKeyErrors) {
  EXPECT_THAT(
      Error("a.yaml", "launch:\n- node:\n    name: x\n    executable: talker\n"),
      AllOf(StartsWith(At("a.yaml", 4, 5)), HasSubstr("unknown key 'executable' in 'node'")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node:\n    name: x\n"),
              AllOf(StartsWith(At("a.yaml", 3, 5)),
                    HasSubstr("'node' is missing 'exec' (expected an executable name)")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node:\n    exec: talker\n    exec: listener\n"),
              AllOf(StartsWith(At("a.yaml", 4, 5)), HasSubstr("duplicate key 'exec' in 'node'")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node:\n    exec: [a, b]\n"),
              AllOf(StartsWith(At("a.yaml", 3, 11)), HasSubstr("'exec' must be a single value")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node:\n    exec: ''\n"),
              AllOf(StartsWith(At("a.yaml", 3, 11)), HasSubstr("empty 'exec'")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, name: 'no-dash'}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 30)), HasSubstr("invalid node name 'no-dash'")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- node: {exec: talker, namespace: 'a//b c'}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 35)), HasSubstr("invalid namespace")));
}

TEST_F(LaunchParserTest, DuplicateNodeNames) {
  EXPECT_THAT(
      Error("a.yaml", "launch:\n- node: {exec: talker}\n- node: {exec: talker}\n"),
      AllOf(StartsWith(At("a.yaml", 3, 9)),
            HasSubstr("duplicate node '/talker' (expected unique names; first declared at " + dir_ +
                      "/a.yaml:2)")));
  // Same name in different namespaces is fine.
  EXPECT_EQ(
      Load("a.yaml", "launch:\n- node: {exec: talker}\n- node: {exec: talker, namespace: x}\n")
          .nodes.size(),
      2u);
}

TEST_F(LaunchParserTest, SetEnvErrors) {
  EXPECT_THAT(Error("a.yaml", "launch:\n- set_env: {name: X}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 12)), HasSubstr("'set_env' is missing 'value'")));
  EXPECT_THAT(Error("a.yaml", "launch:\n- set_env: {name: '', value: 1}\n"),
              AllOf(StartsWith(At("a.yaml", 2, 19)), HasSubstr("invalid environment variable")));
}

// --- in-memory parsing (the fuzzer's entry point) ---

TEST(ParseLaunchText, VirtualFilesAndNoResolution) {
  std::map<std::string, std::string> files{
      {"virtual/inc.yaml", "launch:\n- node: {exec: inner, args: $(dirname)}\n"}};
  ParseOptions options;
  options.resolve_executables = false;
  options.read_file = [&](const std::string& path) -> std::optional<std::string> {
    auto it = files.find(path);
    if (it == files.end()) return std::nullopt;
    return it->second;
  };
  options.file_exists = [](const std::string&) { return true; };
  const auto d = ParseLaunchText(
      "launch:\n- node: {exec: ./outer, param: [{from: p.yaml}]}\n- include: {file: inc.yaml}\n",
      "virtual/top.yaml", options);
  ASSERT_EQ(d.nodes.size(), 2u);
  EXPECT_EQ(d.nodes[0].executable, "./outer");
  EXPECT_EQ(d.nodes[0].name, "outer");
  EXPECT_TRUE(fs::path(d.nodes[0].param_files.at(0)).is_absolute());
  EXPECT_EQ(d.nodes[1].arguments, (Strings{"virtual"}));
  try {
    ParseLaunchText("launch:\n- include: {file: missing.yaml}\n", "virtual/top.yaml", options);
    ADD_FAILURE() << "no error";
  } catch (const LaunchError& e) {
    EXPECT_THAT(e.what(), StartsWith("virtual/top.yaml:2:19: cannot read launch file "
                                     "'virtual/missing.yaml'"));
  }
  try {
    ParseLaunchText("launch:\n- include: {file: top.yaml}\n", "virtual/top.yaml", options);
    ADD_FAILURE() << "no error";
  } catch (const LaunchError& e) {
    EXPECT_THAT(e.what(), StartsWith("virtual/top.yaml:2:19: include cycle virtual/top.yaml -> "
                                     "virtual/top.yaml"));
  }
}

}  // namespace
}  // namespace probeless::launch

namespace probeless::launch {
namespace {

// The example launch files of launch/examples parse (executables unresolved: nodes may not be
// built in every build directory).
TEST(LaunchExamples, AllParse) {
  ParseOptions options;
  options.resolve_executables = false;
  const std::string dir = std::string(PROBELESS_SOURCE_DIR) + "/launch/examples/";
  EXPECT_EQ(LoadLaunchFile(dir + "talker_listener.launch.yaml", options).nodes.size(), 2u);
  EXPECT_EQ(LoadLaunchFile(dir + "shell_demo.launch.yaml", options).nodes.size(), 3u);
  const auto cameras = LoadLaunchFile(dir + "two_cameras.launch.yaml", options);
  ASSERT_EQ(cameras.nodes.size(), 5u);
  EXPECT_EQ(cameras.nodes[2].fully_qualified_name, "/rear/talker");
  EXPECT_TRUE(cameras.nodes[4].required);
  EXPECT_EQ(cameras.nodes[4].param_files, (Strings{dir + "params/camera.yaml"}));
  options.arguments = {{"debug", "true"}};
  const auto debug = LoadLaunchFile(dir + "two_cameras.launch.yaml", options);
  ASSERT_EQ(debug.nodes.size(), 6u);
  EXPECT_EQ(debug.nodes[5].prefix.at(0), "gdb");
}

}  // namespace
}  // namespace probeless::launch
