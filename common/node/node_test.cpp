// Unit tests of the node runtime: arguments, parameters, params files, topic names, logging and
// shutdown (no bus traffic; see node_bus_test.cpp for that).
#include "probeless/node/node.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "probeless/node/data_file.h"
#include "probeless/node/main.h"
#include "probeless/testing/expect.h"

namespace probeless::node {
namespace {

using namespace std::chrono_literals;

// Expectations below assume the default log level: ignore the developer's environment.
[[maybe_unused]] const bool kEnvironmentCleared = (unsetenv("PROBELESS_LOG_LEVEL"), true);

std::vector<std::string> Argv(std::vector<std::string> args) {
  args.insert(args.begin(), "/opt/bin/prog");
  return args;
}

std::string NodeErrorOf(std::vector<std::string> args, std::string_view name = "talker") {
  return probeless::testing::ThrownMessage<NodeError>(
      [&] { Node node(Argv(std::move(args)), name); });
}

// A directory for params files, removed at the end of the test.
class TempDir {
 public:
  TempDir() {
    char pattern[] = "/tmp/probeless_node_test.XXXXXX";
    path_ = mkdtemp(pattern);
  }
  ~TempDir() { std::system(("rm -rf '" + path_ + "'").c_str()); }
  std::string Write(const std::string& name, const std::string& text) const {
    const std::string path = path_ + "/" + name;
    std::ofstream(path) << text;
    return path;
  }

 private:
  std::string path_;
};

// Runs `f` with stderr redirected to a file and returns what was written.
template <class F>
std::string CaptureStderr(F&& f) {
  char path[] = "/tmp/probeless_node_stderr.XXXXXX";
  const int file = mkstemp(path);
  const int saved = dup(STDERR_FILENO);
  dup2(file, STDERR_FILENO);
  f();
  dup2(saved, STDERR_FILENO);
  close(saved);
  close(file);
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  unlink(path);
  return text.str();
}

// Runs `body` in a forked child and returns its wait status.
template <class F>
int RunInChild(F&& body) {
  const pid_t pid = fork();
  if (pid == 0) {
    body();
    _exit(0);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  return status;
}

// --- Arguments ---------------------------------------------------------------------------------

TEST(ArgumentsTest, SeparatesOwnArgumentsFromRosArguments) {
  Node node(Argv({"--width", "640", "--ros-args", "-r", "__node:=cam", "-r", "__ns:=/robot1", "-p",
                  "a:=1", "--", "input.bag", "--ros-args", "--param", "b:=2", "--remap", "x:=y"}),
            "talker");
  EXPECT_EQ(node.program(), "/opt/bin/prog");
  EXPECT_EQ(node.args(), (std::vector<std::string>{"--width", "640", "input.bag"}));
  EXPECT_EQ(node.name(), "cam");
  EXPECT_EQ(node.namespace_(), "/robot1");
  EXPECT_EQ(node.fully_qualified_name(), "/robot1/cam");
  EXPECT_EQ(node.Param<int64_t>("a", 0), 1);
  EXPECT_EQ(node.Param<int64_t>("b", 0), 2);
  EXPECT_EQ(node.ResolveTopicName("x"), "/robot1/y");
}

TEST(ArgumentsTest, DefaultsWithoutRosArguments) {
  Node node(Argv({"-p", "a:=1"}), "talker");  // -p outside --ros-args is the node's own
  EXPECT_EQ(node.args(), (std::vector<std::string>{"-p", "a:=1"}));
  EXPECT_EQ(node.name(), "talker");
  EXPECT_EQ(node.namespace_(), "/");
  EXPECT_EQ(node.fully_qualified_name(), "/talker");
  EXPECT_FALSE(node.HasParamOverride("a"));
}

TEST(ArgumentsTest, FirstMatchingNameRuleWinsAndNodePrefixesFilter) {
  Node a(Argv({"--ros-args", "-r", "other:__node:=x", "-r", "talker:__node:=mine", "-r",
               "__node:=late", "-r", "__name:=later", "-r", "__ns:=/a", "-r", "__ns:=/b"}),
         "talker");
  EXPECT_EQ(a.fully_qualified_name(), "/a/mine");
  Node b(Argv({"--ros-args", "-r", "__name:=legacy"}), "talker");
  EXPECT_EQ(b.name(), "legacy");
  Node c(Argv({"--ros-args", "-r", "__ns:=/"}), "talker");
  EXPECT_EQ(c.fully_qualified_name(), "/talker");
}

TEST(ArgumentsTest, RejectsMalformedArgumentsWithExactMessages) {
  const struct {
    std::vector<std::string> args;
    std::string message;
  } cases[] = {
      {{"--ros-args", "-r"},
       "node 'talker': --ros-args: '-r' must be followed by a remap rule (from:=to)"},
      {{"--ros-args", "--param"},
       "node 'talker': --ros-args: '--param' must be followed by a parameter rule (name:=value)"},
      {{"--ros-args", "--params-file"},
       "node 'talker': --ros-args: '--params-file' must be followed by a file path"},
      {{"--ros-args", "--log-level"},
       "node 'talker': --ros-args: '--log-level' must be followed by a log level"},
      {{"--ros-args", "-r", "foo"},
       "node 'talker': --ros-args: invalid remap rule 'foo' (expected from:=to)"},
      {{"--ros-args", "-r", "foo:="},
       "node 'talker': --ros-args: invalid remap rule 'foo:=' (expected from:=to)"},
      {{"--ros-args", "-r", "__node:=a-b"},
       "node 'talker': --ros-args: invalid node name 'a-b' in '__node:=a-b' (letters, digits and "
       "'_', not starting with a digit)"},
      {{"--ros-args", "-r", "__node:=1st"},
       "node 'talker': --ros-args: invalid node name '1st' in '__node:=1st' (letters, digits and "
       "'_', not starting with a digit)"},
      {{"--ros-args", "-r", "__ns:=robot"},
       "node 'talker': --ros-args: invalid namespace 'robot' in '__ns:=robot' (expected an "
       "absolute name such as /robot1)"},
      {{"--ros-args", "-r", "__ns:=/a/"},
       "node 'talker': --ros-args: invalid namespace '/a/' in '__ns:=/a/' (expected an absolute "
       "name such as /robot1)"},
      {{"--ros-args", "-r", "__nodes:=x"},
       "node 'talker': --ros-args: unknown special name '__nodes' in remap rule '__nodes:=x' "
       "(expected __node or __ns)"},
      {{"--ros-args", "-r", "bad-node:a:=b"},
       "node 'talker': --ros-args: invalid node name 'bad-node' before ':' in remap rule "
       "'bad-node:a:=b'"},
      {{"--ros-args", "-p", "rate"},
       "node 'talker': --ros-args: invalid parameter rule 'rate' (expected name:=value)"},
      {{"--ros-args", "-p", "a b:=1"},
       "node 'talker': --ros-args: invalid parameter name 'a b' in 'a b:=1' (letters, digits, '_' "
       "and single '.')"},
      {{"--ros-args", "-p", "a..b:=1"},
       "node 'talker': --ros-args: invalid parameter name 'a..b' in 'a..b:=1' (letters, digits, "
       "'_' and single '.')"},
      {{"--ros-args", "-p", "a:="},
       "node 'talker': --ros-args: invalid value in parameter rule 'a:=': the value is empty"},
      {{"--ros-args", "-p", "a:=[1,"},
       "node 'talker': --ros-args: invalid value in parameter rule 'a:=[1,': invalid YAML: end "
       "of sequence flow not found"},
      {{"--ros-args", "-p", "a:={x: 1}"},
       "node 'talker': --ros-args: invalid value in parameter rule 'a:={x: 1}': a mapping is not "
       "a parameter value"},
      {{"--ros-args", "-p", "a:=[1, x]"},
       "node 'talker': --ros-args: invalid value in parameter rule 'a:=[1, x]': a list mixes "
       "integer and string elements"},
      {{"--ros-args", "-p", "a:=[[1]]"},
       "node 'talker': --ros-args: invalid value in parameter rule 'a:=[[1]]': a list may only "
       "contain scalars (no nested lists or mappings)"},
      {{"--ros-args", "-p", "a:=99999999999999999999"},
       "node 'talker': --ros-args: invalid value in parameter rule 'a:=99999999999999999999': "
       "integer 99999999999999999999 is out of range"},
      {{"--ros-args", "--log-level", "loud"},
       "node 'talker': --ros-args: invalid log level 'loud' (expected debug, info, warn or "
       "error)"},
      {{"--ros-args", "--enclave", "/x"},
       "node 'talker': --ros-args: unknown argument '--enclave' (supported: -r/--remap, "
       "-p/--param, --params-file, --log-level, --)"},
      {{"--ros-args", "-r", "a//b:=c"},
       "node '/talker': remap rule 'a//b:=c': invalid topic name 'a//b' (expected segments of "
       "letters, digits and '_' not starting with a digit, separated by single '/', optionally "
       "starting with '/' or '~/')"},
  };
  for (const auto& c : cases) {
    EXPECT_EQ(NodeErrorOf(c.args), c.message) << c.args.back();
  }
  EXPECT_EQ(NodeErrorOf({}, "bad name"),
            "invalid default node name 'bad name' (letters, digits and '_', not starting with a "
            "digit)");
}

// --- Parameters --------------------------------------------------------------------------------

TEST(ParamsTest, TypesFromCommandLine) {
  Node node(Argv({"--ros-args",
                  "-p",
                  "flag:=true",
                  "-p",
                  "yes_flag:=yes",
                  "-p",
                  "count:=-42",
                  "-p",
                  "ratio:=0.25",
                  "-p",
                  "whole:=3",
                  "-p",
                  "name:=camera_1",
                  "-p",
                  "quoted:='007'",
                  "-p",
                  "doubles:=[1, 2.5, -3]",
                  "-p",
                  "ints:=[4, 5]",
                  "-p",
                  "names:=[a, 'b c']",
                  "-p",
                  "ints_as_doubles:=[4, 5]",
                  "-p",
                  "empty:=[]",
                  "-p",
                  "big:=1e3",
                  "-p",
                  "inf:=.inf",
                  "-p",
                  "spaced:=hello world"}),
            "talker");
  EXPECT_EQ(node.Param("flag", false), true);
  EXPECT_EQ(node.Param("yes_flag", false), true);
  EXPECT_EQ(node.Param<int64_t>("count", 0), -42);
  EXPECT_EQ(node.Param<int>("count", 0), -42);
  EXPECT_EQ(node.Param("ratio", 1.0), 0.25);
  EXPECT_EQ(node.Param("whole", 1.0), 3.0);  // an integer is accepted for a double
  EXPECT_EQ(node.Param("name", "x"), "camera_1");
  EXPECT_EQ(node.Param("quoted", "x"), "007");  // quoted: stays a string
  EXPECT_EQ(node.Param("doubles", std::vector<double>{}), (std::vector<double>{1, 2.5, -3}));
  EXPECT_EQ(node.Param("ints", std::vector<int64_t>{}), (std::vector<int64_t>{4, 5}));
  EXPECT_EQ(node.Param("ints_as_doubles", std::vector<double>{9}), (std::vector<double>{4, 5}));
  EXPECT_EQ(node.Param("names", std::vector<std::string>{}),
            (std::vector<std::string>{"a", "b c"}));
  EXPECT_EQ(node.Param("empty", std::vector<std::string>{"z"}), std::vector<std::string>{});
  EXPECT_EQ(node.Param("big", 0.0), 1000.0);
  EXPECT_TRUE(std::isinf(node.Param("inf", 0.0)));
  EXPECT_EQ(node.Param("spaced", ""), "hello world");
  EXPECT_EQ(node.Param("unset", 7.5), 7.5);
}

TEST(ParamsTest, WrongTypesNameNodeParamExpectedAndActual) {
  Node node(Argv({"--ros-args", "-r", "__ns:=/cam", "-p", "rate:=fast", "-p", "n:=1.5", "-p",
                  "huge:=5000000000", "-p", "list:=[1, 2]", "-p", "flag:=1"}),
            "talker");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      node.Param("rate", 10.0), NodeError,
      "node '/cam/talker': parameter 'rate' has type string (value \"fast\", from -p), "
      "expected double");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      node.Param<int64_t>("n", 1), NodeError,
      "node '/cam/talker': parameter 'n' has type double (value 1.5, from -p), expected "
      "integer");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      node.Param<int>("huge", 1), NodeError,
      "node '/cam/talker': parameter 'huge' value 5000000000 (from -p) is out of range for "
      "int32");
  EXPECT_EQ(node.Param<int64_t>("huge", 1), 5'000'000'000);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      node.Param("list", std::vector<std::string>{}), NodeError,
      "node '/cam/talker': parameter 'list' has type integer_array (value [1, 2], from -p), "
      "expected string_array");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      node.Param("flag", false), NodeError,
      "node '/cam/talker': parameter 'flag' has type integer (value 1, from -p), expected "
      "bool");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      node.RequireParam<std::string>("device"), NodeError,
      "node '/cam/talker': required parameter 'device' (string) is not set (give it with -p "
      "or a params file)");
  node.Param("width", int64_t{640});
  PROBELESS_EXPECT_THROWS_MESSAGE(
      node.Param("width", 1.0), NodeError,
      "node '/cam/talker': parameter 'width' declared as integer, now requested as double");
}

TEST(ParamsTest, RequireParamAndIntrospection) {
  Node node(Argv({"--ros-args", "-p", "device:=/dev/video0", "-p", "typo_rate:=5", "-p",
                  "gains:=[1.0, 2.0]"}),
            "talker");
  EXPECT_EQ(node.RequireParam<std::string>("device"), "/dev/video0");
  EXPECT_EQ(node.Param("rate", 30.0), 30.0);
  EXPECT_EQ(node.Param("gains", std::vector<double>{}), (std::vector<double>{1, 2}));
  EXPECT_EQ(node.Param("labels", std::vector<std::string>{"a", "b"}),
            (std::vector<std::string>{"a", "b"}));
  const std::vector<ParamInfo> declared = node.DeclaredParams();
  ASSERT_EQ(declared.size(), 5u);
  EXPECT_EQ(declared[0].name, "log_level");
  EXPECT_EQ(declared[0].value, "info");
  EXPECT_EQ(declared[0].source, "default");
  EXPECT_EQ(declared[1].name, "device");
  EXPECT_EQ(declared[1].type, "string");
  EXPECT_EQ(declared[1].value, "/dev/video0");
  EXPECT_EQ(declared[1].source, "-p");
  EXPECT_EQ(declared[2].name, "rate");
  EXPECT_EQ(declared[2].type, "double");
  EXPECT_EQ(declared[2].value, "30.0");
  EXPECT_EQ(declared[2].source, "default");
  EXPECT_EQ(declared[3].type, "double_array");
  EXPECT_EQ(declared[3].value, "[1.0, 2.0]");
  EXPECT_EQ(declared[4].type, "string_array");
  EXPECT_EQ(declared[4].value, "[\"a\", \"b\"]");
  EXPECT_EQ(node.UnusedParamOverrides(), std::vector<std::string>{"typo_rate"});
}

TEST(ParamsTest, DescriptorsCheckRangesAndChoicesOfTheEffectiveValue) {
  Node node(Argv({"--ros-args", "-p", "bands:=12", "-p", "rate:=0", "-p", "mode:=fast", "-p",
                  "gains:=[0.5, 3.0]", "-p", "ok_rate:=2.5"}),
            "talker");
  const ParamDescriptor bands{.description = "SH bands", .min = 1.0, .max = 8.0};
  PROBELESS_EXPECT_THROWS_MESSAGE(node.Param("bands", 4, bands), NodeError,
                                  "node '/talker': parameter 'bands' = 12 (from -p) is out of "
                                  "range: expected a value in [1, 8]");
  const ParamDescriptor rate{.unit = "Hz", .min = 0.0, .min_exclusive = true};
  PROBELESS_EXPECT_THROWS_MESSAGE(node.Param("rate", 30.0, rate), NodeError,
                                  "node '/talker': parameter 'rate' = 0.0 (from -p) is out of "
                                  "range: expected a value in (0, inf) Hz");
  EXPECT_EQ(node.Param("ok_rate", 30.0, rate), 2.5);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      node.Param("mode", "gbuffer", {.choices = {"gbuffer", "depth"}}), NodeError,
      "node '/talker': parameter 'mode' = \"fast\" (from -p) is not one of gbuffer|depth");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      node.Param("gains", std::vector<double>{}, {.min = 0.0, .max = 2.0}), NodeError,
      "node '/talker': parameter 'gains' = [0.5, 3.0] (from -p) is out of range: expected every "
      "element in [0, 2]");
  // The default is checked too: a default outside its own range is refused the same way.
  PROBELESS_EXPECT_THROWS_MESSAGE(node.Param("lamps", -1, {.min = 0.0}), NodeError,
                                  "node '/talker': parameter 'lamps' = -1 (from default) is out "
                                  "of range: expected a value in [0, inf)");
  PROBELESS_EXPECT_THROWS_MESSAGE(node.Param("gain", std::nan(""), {.max = 1.0}), NodeError,
                                  "node '/talker': parameter 'gain' = .nan (from default) is out "
                                  "of range: expected a value in (-inf, 1]");
  EXPECT_EQ(node.Param("radius", 0.3, {.description = "SSDO radius", .unit = "m", .min = 0.0}),
            0.3);
  const std::vector<ParamInfo> declared = node.DeclaredParams();
  const auto find = [&](std::string_view name) {
    for (const ParamInfo& info : declared) {
      if (info.name == name) return info;
    }
    return ParamInfo{};
  };
  EXPECT_EQ(find("radius").description, "SSDO radius");
  EXPECT_EQ(find("radius").unit, "m");
  EXPECT_EQ(find("radius").constraint, "[0, inf)");
  EXPECT_EQ(find("ok_rate").constraint, "(0, inf)");
  EXPECT_EQ(find("log_level").constraint, "");
}

TEST(ParamsTest, ChoicesApplyToEveryElementOfAStringArray) {
  Node node(Argv({"--ros-args", "-p", "topics:=[image, dpeth]"}), "talker");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      node.Param("topics", std::vector<std::string>{}, {.choices = {"image", "depth"}}), NodeError,
      "node '/talker': parameter 'topics' = [\"image\", \"dpeth\"] (from -p) has an element that "
      "is not one of image|depth");
}

TEST(ParamsTest, CheckParamOverridesNamesTheUnknownOneAndTheNearestDeclaredName) {
  {
    Node node(Argv({"--ros-args", "-p", "bandz:=3"}), "talker");
    node.Param("bands", 4);
    node.Param("rate", 30.0);
    PROBELESS_EXPECT_THROWS_MESSAGE(
        node.CheckParamOverrides(), NodeError,
        "node '/talker': unknown parameter 'bandz' (from -p); did you mean 'bands'?");
  }
  {
    Node node(Argv({"--ros-args", "-p", "completely_else:=3"}), "talker");
    node.Param("bands", 4);
    PROBELESS_EXPECT_THROWS_MESSAGE(node.CheckParamOverrides(), NodeError,
                                    "node '/talker': unknown parameter 'completely_else' (from "
                                    "-p); this node declares no parameter of that name");
  }
  {
    Node node(Argv({"--ros-args", "-p", "bands:=3"}), "talker");
    node.Param("bands", 4);
    EXPECT_NO_THROW(node.CheckParamOverrides());
  }
}

TEST(ParamsTest, CheckParamOverridesLeavesWildcardEntriesToTheNodesThatReadThem) {
  TempDir dir;
  const std::string file = dir.Write("shared.yaml", R"(
/**:
  ros__parameters:
    use_sim_time: true
    rate: 5
talker:
  ros__parameters:
    sped: 2
)");
  {
    Node node(Argv({"--ros-args", "--params-file", file}), "talker");
    node.Param("speed", 1);
    PROBELESS_EXPECT_THROWS_MESSAGE(node.CheckParamOverrides(), NodeError,
                                    "node '/talker': unknown parameter 'sped' (from params file '" +
                                        file + "'); did you mean 'speed'?");
  }
  {
    // use_sim_time (wildcard only) is not this node's; rate, set again by -p, is checked.
    Node node(Argv({"--ros-args", "--params-file", file, "-p", "rate:=7", "-p", "sped:=1"}),
              "talker");
    node.Param("sped", 1);
    PROBELESS_EXPECT_THROWS_MESSAGE(node.CheckParamOverrides(), NodeError,
                                    "node '/talker': unknown parameter 'rate' (from -p); this node "
                                    "declares no parameter of that name");
    node.Param("rate", 1);
    EXPECT_NO_THROW(node.CheckParamOverrides());
  }
  {
    // An exact entry stays checked when a later file's wildcard entry sets the same name.
    const std::string later = dir.Write("later.yaml", R"(
/**:
  ros__parameters:
    sped: 3
)");
    Node node(Argv({"--ros-args", "--params-file", file, "--params-file", later}), "talker");
    node.Param("speed", 1);
    node.Param("rate", 1);
    PROBELESS_EXPECT_THROWS_MESSAGE(node.CheckParamOverrides(), NodeError,
                                    "node '/talker': unknown parameter 'sped' (from params file '" +
                                        later + "'); did you mean 'speed'?");
  }
}

TEST(ParamsTest, PrecedenceCommandLineOverFilesOverDefault) {
  TempDir dir;
  const std::string first = dir.Write("first.yaml", R"(
/**:
  ros__parameters:
    a: 1
    b: 1
    c: 1
    d: 1
talker:
  ros__parameters:
    b: 2
/**/talker:
  ros__parameters:
    b: 3      # wildcard: applied before the exact "talker" entry, so b stays 2
)");
  const std::string second = dir.Write("second.yaml", R"(
/talker:
  ros__parameters:
    c: 20
    d: 20
)");
  Node node(Argv({"--ros-args", "--params-file", first, "-p", "d:=300", "--params-file", second}),
            "talker");
  EXPECT_EQ(node.Param<int64_t>("a", 0), 1);    // from the wildcard entry of the first file
  EXPECT_EQ(node.Param<int64_t>("b", 0), 2);    // exact entry beats wildcards within a file
  EXPECT_EQ(node.Param<int64_t>("c", 0), 20);   // the later file beats the earlier one
  EXPECT_EQ(node.Param<int64_t>("d", 0), 300);  // -p beats every file, wherever it appears
  EXPECT_EQ(node.Param<int64_t>("e", 5), 5);    // default
  const std::vector<ParamInfo> declared = node.DeclaredParams();
  EXPECT_EQ(declared[1].source, "params file '" + first + "'");
  EXPECT_EQ(declared[3].source, "params file '" + second + "'");
  EXPECT_EQ(declared[4].source, "-p");
}

TEST(ParamsTest, ParamsFileFormats) {
  TempDir dir;
  const std::string path = dir.Write("p.yaml", R"(
robot1:                     # namespace key, then node key
  camera:
    ros__parameters:
      device: /dev/video2
      size:                 # nested mapping -> "size.width", "size.height"
        width: 1280
        height: 720
      gains: [0.5, 1]
      names:
        - left
        - "right"
      enabled: on
/robot1/*:
  ros__parameters:
    shared: "yes"
/robot2/camera:
  ros__parameters:
    device: /dev/other
/**/cam*:
  ros__parameters:
    glob: true
)");
  Node node(Argv({"--ros-args", "-r", "__ns:=/robot1", "--params-file", path}), "camera");
  EXPECT_EQ(node.Param("device", ""), "/dev/video2");
  EXPECT_EQ(node.Param<int64_t>("size.width", 0), 1280);
  EXPECT_EQ(node.Param<int>("size.height", 0), 720);
  EXPECT_EQ(node.Param("gains", std::vector<double>{}), (std::vector<double>{0.5, 1}));
  EXPECT_EQ(node.Param("names", std::vector<std::string>{}),
            (std::vector<std::string>{"left", "right"}));
  EXPECT_TRUE(node.Param("enabled", false));
  EXPECT_EQ(node.Param("shared", ""), "yes");  // quoted: a string, not a bool
  EXPECT_TRUE(node.Param("glob", false));

  Node other(Argv({"--ros-args", "-r", "__ns:=/robot1/deep", "--params-file", path}), "camera");
  EXPECT_FALSE(other.HasParamOverride("device"));  // "/robot1/camera" is exact
  EXPECT_FALSE(other.HasParamOverride("shared"));  // "*" matches exactly one token
  EXPECT_TRUE(other.HasParamOverride("glob"));     // "**" matches any number
}

TEST(ParamsTest, ParamsFileErrors) {
  TempDir dir;
  const std::string missing = "/nonexistent/params.yaml";
  EXPECT_EQ(NodeErrorOf({"--ros-args", "--params-file", missing}),
            "node '/talker': params file '/nonexistent/params.yaml': cannot open the file");
  const struct {
    std::string text;
    std::string message;
  } cases[] = {
      {"talker: [1, 2\n", "line 2, column 1: end of sequence flow not found"},
      {"- a\n- b\n", "the top level must map node names to 'ros__parameters'"},
      {"talker: 5\n",
       "'/talker' must be a mapping holding 'ros__parameters' (or nested node names)"},
      {"ros__parameters:\n  a: 1\n", "'ros__parameters' must be under a node name"},
      {"talker:\n  ros__parameters: [1]\n", "'ros__parameters' of '/talker' must be a mapping"},
      {"talker:\n  ros__parameters:\n    a: [1, true]\n",
       "parameter 'a' of '/talker': a list mixes integer and bool elements"},
      {"talker:\n  ros__parameters:\n    a:\n", "parameter 'a' of '/talker': the value is empty"},
  };
  int i = 0;
  for (const auto& c : cases) {
    const std::string path = dir.Write("bad" + std::to_string(i++) + ".yaml", c.text);
    EXPECT_EQ(NodeErrorOf({"--ros-args", "--params-file", path}),
              "node '/talker': params file '" + path + "': " + c.message);
  }
  // An empty file is fine.
  const std::string empty = dir.Write("empty.yaml", "");
  Node node(Argv({"--ros-args", "--params-file", empty}), "talker");
  EXPECT_TRUE(node.UnusedParamOverrides().empty());
}

TEST(ParamsTest, NodePrefixedParamRulesApplyOnlyToThatNode) {
  const std::vector<std::string> args = {"--ros-args",     "-p", "listener:rate:=5", "-p",
                                         "talker:rate:=7", "-p", "rate_all:=1"};
  Node talker(Argv(args), "talker");
  Node listener(Argv(args), "listener");
  EXPECT_EQ(talker.Param<int64_t>("rate", 0), 7);
  EXPECT_EQ(listener.Param<int64_t>("rate", 0), 5);
  EXPECT_EQ(listener.Param<int64_t>("rate_all", 0), 1);
}

// --- Topic names -------------------------------------------------------------------------------

TEST(TopicNamesTest, ResolutionAndRemapsTable) {
  const struct {
    std::string ns;
    std::vector<std::string> remaps;
    std::string input;
    std::string expected;
  } cases[] = {
      {"/", {}, "image", "/image"},
      {"/", {}, "/image", "/image"},
      {"/", {}, "~", "/talker"},
      {"/", {}, "~/debug", "/talker/debug"},
      {"/robot1", {}, "image", "/robot1/image"},
      {"/robot1", {}, "camera/image", "/robot1/camera/image"},
      {"/robot1", {}, "/image", "/image"},
      {"/robot1", {}, "~/debug", "/robot1/talker/debug"},
      {"/robot1", {}, "{node}/out", "/robot1/talker/out"},
      {"/robot1", {}, "{ns}/x", "/robot1/x"},
      {"/robot1", {}, "/out/{node}", "/out/talker"},
      {"/", {}, "{ns}/x", "/x"},
      // Remaps: both sides are expanded with the node's namespace, first match wins.
      {"/robot1", {"image:=raw"}, "image", "/robot1/raw"},
      {"/robot1", {"image:=/global"}, "image", "/global"},
      {"/robot1", {"/robot1/image:=other"}, "image", "/robot1/other"},
      {"/robot1", {"image:=a", "image:=b"}, "image", "/robot1/a"},
      {"/robot1", {"image:=a"}, "/image", "/image"},  // "/image" != "/robot1/image"
      {"/robot1", {"~/debug:=dbg"}, "~/debug", "/robot1/dbg"},
      {"/robot1", {"chatter:=~/mine"}, "chatter", "/robot1/talker/mine"},
      {"/robot1", {"talker:image:=t"}, "image", "/robot1/t"},
      {"/robot1", {"listener:image:=l"}, "image", "/robot1/image"},
      {"/robot1", {"image:=raw"}, "images", "/robot1/images"},
  };
  for (const auto& c : cases) {
    std::vector<std::string> args = {"--ros-args", "-r", "__ns:=" + c.ns};
    for (const std::string& r : c.remaps) {
      args.push_back("-r");
      args.push_back(r);
    }
    Node node(Argv(args), "talker");
    EXPECT_EQ(node.ResolveTopicName(c.input), c.expected) << "ns " << c.ns << ", input " << c.input;
  }
}

TEST(TopicNamesTest, InvalidNamesThrowExactMessages) {
  Node node(Argv({}), "talker");
  const std::string rules =
      " (expected segments of letters, digits and '_' not starting with a digit, separated by "
      "single '/', optionally starting with '/' or '~/')";
  for (const std::string name : {"a//b", "a/", "/", "a b", "a.b", "~x", "1abc", "/a/2b", "a-b"}) {
    PROBELESS_EXPECT_THROWS_MESSAGE(node.ResolveTopicName(name), NodeError,
                                    "node '/talker': invalid topic name '" + name + "'" + rules);
  }
  PROBELESS_EXPECT_THROWS_MESSAGE(node.ResolveTopicName(""), NodeError,
                                  "node '/talker': invalid topic name '': empty");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      node.ResolveTopicName("{robot}/x"), NodeError,
      "node '/talker': invalid topic name '{robot}/x': unknown substitution '{robot}' "
      "(expected {node}, {ns} or {namespace})");
  // Length is checked by the bus's own validation.
  PROBELESS_EXPECT_THROWS_MESSAGE_THAT(
      node.ResolveTopicName(std::string(120, 'x')), NodeError,
      ::testing::AllOf(::testing::StartsWith("node '/talker': invalid topic name '/xxx"),
                       ::testing::HasSubstr("longer than 100")));
}

// --- Logging -----------------------------------------------------------------------------------

TEST(LoggingTest, FormatAndLevelFiltering) {
  Node node(Argv({"--ros-args", "-r", "__ns:=/cam"}), "talker");
  EXPECT_EQ(node.log_level(), LogLevel::kInfo);
  const std::string out = CaptureStderr([&] {
    node.Info() << "published " << 10 << " frames";
    node.Debug() << "hidden";
    node.Warn() << "slow";
    node.Log(LogLevel::kError, "broken");
    node.set_log_level(LogLevel::kDebug);
    node.Debug() << "shown " << 1.5;
  });
  EXPECT_EQ(out,
            "[info] [/cam/talker] published 10 frames\n"
            "[warn] [/cam/talker] slow\n"
            "[error] [/cam/talker] broken\n"
            "[debug] [/cam/talker] shown 1.5\n");
}

TEST(LoggingTest, LevelFromParamFlagOrEnvironment) {
  setenv("PROBELESS_LOG_LEVEL", "error", 1);
  EXPECT_EQ(Node(Argv({}), "talker").log_level(), LogLevel::kError);
  EXPECT_EQ(Node(Argv({"--ros-args", "--log-level", "WARN"}), "talker").log_level(),
            LogLevel::kWarn);
  EXPECT_EQ(Node(Argv({"--ros-args", "--log-level", "other:=debug"}), "talker").log_level(),
            LogLevel::kError);
  EXPECT_EQ(Node(Argv({"--ros-args", "--log-level", "talker:=debug"}), "talker").log_level(),
            LogLevel::kDebug);
  EXPECT_EQ(Node(Argv({"--ros-args", "--log-level", "warn", "-p", "log_level:=debug"}), "talker")
                .log_level(),
            LogLevel::kDebug);
  setenv("PROBELESS_LOG_LEVEL", "chatty", 1);
  EXPECT_EQ(NodeErrorOf({}),
            "node '/talker': invalid log level 'chatty' (expected debug, info, warn or error) from "
            "PROBELESS_LOG_LEVEL");
  unsetenv("PROBELESS_LOG_LEVEL");
  EXPECT_EQ(NodeErrorOf({"--ros-args", "-p", "log_level:=loud"}),
            "node '/talker': invalid log level 'loud' (expected debug, info, warn or error) from "
            "-p");
  EXPECT_EQ(NodeErrorOf({"--ros-args", "-p", "log_level:=3"}),
            "node '/talker': parameter 'log_level' has type integer (value 3, from -p), expected "
            "string");
  Node node(Argv({"--ros-args", "-p", "log_level:=warn"}), "talker");
  EXPECT_EQ(node.DeclaredParams()[0].value, "warn");
  EXPECT_EQ(node.DeclaredParams()[0].source, "-p");
}

TEST(LoggingTest, ConcurrentLinesStayWhole) {
  Node node(Argv({}), "talker");
  const std::string out = CaptureStderr([&] {
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t) {
      threads.emplace_back([&, t] {
        for (int i = 0; i < 200; ++i) node.Info() << "thread " << t << " line " << i << " end";
      });
    }
    for (std::thread& t : threads) t.join();
  });
  std::istringstream lines(out);
  std::string line;
  int count = 0;
  while (std::getline(lines, line)) {
    ++count;
    ASSERT_TRUE(line.starts_with("[info] [/talker] thread ") && line.ends_with(" end")) << line;
  }
  EXPECT_EQ(count, 800);
}

// --- Shutdown ----------------------------------------------------------------------------------

TEST(ShutdownTest, SigintClearsOkAndSecondSigintExits130) {
  const int status = RunInChild([] {
    Node node(Argv({}), "talker");
    if (!node.ok()) _exit(10);
    raise(SIGINT);
    if (node.ok() || ok()) _exit(11);
    if (!node.WaitForShutdown(10s)) _exit(12);  // returns at once: already requested
    raise(SIGINT);                              // second signal: immediate exit(130)
    _exit(13);
  });
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 130);
}

TEST(ShutdownTest, SigtermClearsOk) {
  const int status = RunInChild([] {
    Node node(Argv({}), "talker");
    raise(SIGTERM);
    _exit(node.ok() ? 1 : 0);
  });
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
}

TEST(ShutdownTest, WaitForShutdownWakesPromptlyOnSignal) {
  const int status = RunInChild([] {
    Node node(Argv({}), "talker");
    if (node.WaitForShutdown(50ms)) _exit(20);  // times out: nothing requested yet
    std::thread killer([] {
      std::this_thread::sleep_for(100ms);
      kill(getpid(), SIGINT);
    });
    const auto start = std::chrono::steady_clock::now();
    const bool stopped = node.WaitForShutdown(10s);
    const auto waited = std::chrono::steady_clock::now() - start;
    killer.join();
    if (!stopped) _exit(21);
    if (waited < 90ms || waited > 2s) _exit(22);  // woke by the signal, not the timeout
    _exit(0);
  });
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
}

TEST(ShutdownTest, RateSleepsAndStopsOnRequest) {
  PROBELESS_EXPECT_THROWS_MESSAGE(Rate rate(0), NodeError,
                                  "invalid rate 0 Hz (expected a finite value > 0)");
  PROBELESS_EXPECT_THROWS_MESSAGE(Rate rate(std::nan("")), NodeError,
                                  "invalid rate nan Hz (expected a finite value > 0)");
  const int status = RunInChild([] {
    Rate rate(100);
    if (rate.period() != 10ms) _exit(30);
    const auto start = std::chrono::steady_clock::now();
    for (int i = 0; i < 10; ++i) {
      if (!rate.Sleep()) _exit(31);
    }
    const auto elapsed = std::chrono::steady_clock::now() - start;
    if (elapsed < 95ms || elapsed > 1s) _exit(32);
    RequestShutdown();
    if (rate.Sleep()) _exit(33);
    _exit(0);
  });
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
}

// The shared main: bad input is exit 2 with one line, anything else exit 1.
TEST(RunMainTest, MapsExceptionsToExitCodesAndOneLine) {
  struct FormatError : InputError {
    using InputError::InputError;
  };
  struct CorruptState : std::runtime_error {
    using std::runtime_error::runtime_error;
  };
  EXPECT_EQ(RunMain("t", [] { return 7; }), 7);
  ::testing::internal::CaptureStderr();
  EXPECT_EQ(RunMain("t", []() -> int { throw UsageError("--rate needs a value"); }), 2);
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "[error] [t] --rate needs a value\n");
  EXPECT_EQ(RunMain("t", []() -> int { throw NodeError("bad param"); }), 2);
  EXPECT_EQ(RunMain("t", []() -> int { throw FormatError("x.mcap: bad magic"); }), 2);
  EXPECT_EQ(RunMain("t", []() -> int { throw std::invalid_argument("stoi"); }), 2);
  EXPECT_EQ(RunMain("t", []() -> int { throw CorruptState("index past the end"); }), 1);
  ::testing::internal::CaptureStderr();
  EXPECT_EQ(RunMain("t", []() -> int { throw std::runtime_error("disk full"); }), 1);
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "[error] [t] disk full\n");
}

TEST(RunMainTest, ParseNumberOption) {
  EXPECT_DOUBLE_EQ(ParseNumberOption("--rate", "2.5"), 2.5);
  EXPECT_DOUBLE_EQ(ParseNumberOption("--n", "-3"), -3);
  for (const char* bad : {"", "fast", "2x", "nan", "inf"}) {
    PROBELESS_EXPECT_THROWS_MESSAGE(ParseNumberOption("--rate", bad), UsageError,
                                    std::string("--rate expects a number, got '") + bad + "'");
  }
}

// The shipped data are found from any working directory; what is not there is left as given, so
// that the loader's error names the user's path.
TEST(DataFileTest, ResolvesShippedDataFromAnyDirectoryAndLeavesTheRest) {
  namespace fs = std::filesystem;
  const fs::path before = fs::current_path();
  const fs::path dir =
      fs::temp_directory_path() / ("probeless_data_file_" + std::to_string(getpid()));
  fs::create_directories(dir);
  fs::current_path(dir);
  const std::string shipped = "data/face_light/default_model.txt";
  const std::string resolved = ResolveDataFile(shipped);
  std::ofstream(dir / "local.txt") << "x";
  const std::string local = ResolveDataFile("local.txt");
  const std::string missing = ResolveDataFile("data/no_such_model.txt");
  fs::current_path(before);
  fs::remove_all(dir);
  EXPECT_TRUE(fs::path(resolved).is_absolute()) << resolved;
  EXPECT_TRUE(fs::exists(resolved)) << resolved;
  EXPECT_TRUE(resolved.ends_with("/" + shipped)) << resolved;
  EXPECT_EQ(local, "local.txt");  // the working directory comes first
  EXPECT_EQ(missing, "data/no_such_model.txt");
  EXPECT_EQ(ResolveDataFile(""), "");
  EXPECT_EQ(ResolveDataFile("/no/such/file"), "/no/such/file");
}

}  // namespace
}  // namespace probeless::node
