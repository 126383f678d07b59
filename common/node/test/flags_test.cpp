// Unit tests of probeless/node/flags.h: the flag parser of the tools (issue #21).
#include "probeless/node/flags.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "probeless/testing/expect.h"

namespace probeless::node {
namespace {

using ::testing::HasSubstr;

// The flags of one imaginary tool, with their defaults.
struct Tool {
  std::string scenes = "eval-world/test";
  std::string json;
  bool quiet = false;
  bool flow = true;
  int frames = 200;
  uint64_t seed = 7;
  double ridge = 0.5;
  double fps = 30;
  float scale = 1;
  std::vector<std::string> light_params;
  std::string mode = "gbuffer";
  int width = 0, height = 0;
  std::string input;
  std::vector<std::string> rest;
  FlagParser flags{"tool", "does one thing well"};

  Tool() {
    flags.Add("--scenes", &scenes, "DIR", "scene folders");
    flags.Add("--json", &json, "OUT", "write the figures here");
    flags.Add("--quiet", &quiet, "no progress lines");
    flags.AddSwitch(
        "--no-flow", [this] { flow = false; }, "without flow tracking");
    flags.Add("--frames", &frames, "N", "frames to time", 1);
    flags.Add("--seed", &seed, "S", "random seed");
    flags.Add("--ridge", &ridge, "X", "regularisation", 0, 1);
    flags.Add("--scale", &scale, "X", "object scale");
    flags.AddPositive("--fps", &fps, "F", "frame rate");
    flags.Add("--light-param", &light_params, "K:=V", "a scene_light parameter");
    flags.AddChoice("--mode", &mode, {"gbuffer", "depth"}, "scene_light input");
    flags.AddCallback(
        "--size", "WxH", "image size",
        [this](const std::string& text) {
          const size_t x = text.find('x');
          if (x == std::string::npos) throw UsageError("--size expects WxH, got '" + text + "'");
          width = parse::ParseInteger<int>("--size", text.substr(0, x), 1);
          height = parse::ParseInteger<int>("--size", text.substr(x + 1), 1);
        },
        "640x480");
  }

  bool Parse(std::vector<std::string> args) {
    args.insert(args.begin(), "/opt/bin/tool");
    std::vector<const char*> argv;
    for (const auto& arg : args) argv.push_back(arg.c_str());
    return flags.Parse(static_cast<int>(argv.size()), argv.data());
  }

  std::string Error(std::vector<std::string> args) {
    return probeless::testing::ThrownMessage<UsageError>([&] { Parse(std::move(args)); });
  }
};

// Runs `f` with stdout redirected to a file and returns what was written.
template <class F>
std::string CaptureStdout(F&& f) {
  char path[] = "/tmp/probeless_flags_stdout.XXXXXX";
  const int file = mkstemp(path);
  std::fflush(stdout);
  const int saved = dup(STDOUT_FILENO);
  dup2(file, STDOUT_FILENO);
  f();
  std::fflush(stdout);
  dup2(saved, STDOUT_FILENO);
  close(saved);
  close(file);
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  unlink(path);
  return text.str();
}

// One line of the usage: the flag indented by 2, its help at column 32.
std::string Line(const std::string& left, const std::string& help) {
  return "\n  " + left + std::string(30 - left.size(), ' ') + help + "\n";
}

TEST(FlagParser, WithoutArgumentsKeepsTheDefaults) {
  Tool t;
  EXPECT_TRUE(t.Parse({}));
  EXPECT_EQ(t.scenes, "eval-world/test");
  EXPECT_EQ(t.frames, 200);
  EXPECT_FALSE(t.quiet);
  EXPECT_TRUE(t.flow);
  EXPECT_EQ(t.mode, "gbuffer");
  EXPECT_TRUE(t.light_params.empty());
  EXPECT_FALSE(t.flags.Given("--scenes"));
}

TEST(FlagParser, StoresEveryKindOfFlag) {
  Tool t;
  EXPECT_TRUE(t.Parse({"--scenes", "a/b", "--quiet", "--no-flow", "--frames", "12", "--seed",
                       "18446744073709551615", "--ridge", "0.25", "--scale", "-2.5", "--fps",
                       "12.5", "--mode", "depth", "--size", "320x240"}));
  EXPECT_EQ(t.scenes, "a/b");
  EXPECT_TRUE(t.quiet);
  EXPECT_FALSE(t.flow);
  EXPECT_EQ(t.frames, 12);
  EXPECT_EQ(t.seed, UINT64_MAX);
  EXPECT_DOUBLE_EQ(t.ridge, 0.25);
  EXPECT_FLOAT_EQ(t.scale, -2.5f);
  EXPECT_DOUBLE_EQ(t.fps, 12.5);
  EXPECT_EQ(t.mode, "depth");
  EXPECT_EQ(t.width, 320);
  EXPECT_EQ(t.height, 240);
  EXPECT_TRUE(t.flags.Given("--scenes"));
  EXPECT_TRUE(t.flags.Given("--quiet"));
  EXPECT_FALSE(t.flags.Given("--json"));
}

TEST(FlagParser, ParsesANodesOwnArgumentsWithoutTheProgramName) {
  Tool t;
  const std::vector<std::string> args{"--frames", "12", "a/b"};
  t.flags.AddPositional("INPUT", &t.input, "the input");
  EXPECT_TRUE(t.flags.Parse(args));
  EXPECT_EQ(t.frames, 12);
  EXPECT_EQ(t.input, "a/b");
  EXPECT_EQ(probeless::testing::ThrownMessage<UsageError>(
                [&] { t.flags.Parse(std::vector<std::string>{"--frames"}); }),
            "--frames needs a value N");
}

TEST(FlagParser, AcceptsTheEqualsForm) {
  Tool t;
  EXPECT_TRUE(t.Parse({"--scenes=x=y", "--frames=3", "--json=", "--light-param=a:=1"}));
  EXPECT_EQ(t.scenes, "x=y");  // only the first '=' separates
  EXPECT_EQ(t.frames, 3);
  EXPECT_EQ(t.json, "");
  EXPECT_TRUE(t.flags.Given("--json"));
  EXPECT_EQ(t.light_params, std::vector<std::string>{"a:=1"});
}

TEST(FlagParser, TheNextArgumentIsTheValueWhateverItLooksLike) {
  Tool t;
  EXPECT_TRUE(t.Parse({"--scale", "-3", "--json", "--quiet"}));
  EXPECT_FLOAT_EQ(t.scale, -3);
  EXPECT_EQ(t.json, "--quiet");
  EXPECT_FALSE(t.quiet);
}

TEST(FlagParser, RepeatedFlagsCollectOrTheLastWins) {
  Tool t;
  EXPECT_TRUE(t.Parse({"--light-param", "a:=1", "--frames", "5", "--light-param=b:=2", "--frames",
                       "6", "--light-param", "a:=3"}));
  EXPECT_EQ(t.light_params, (std::vector<std::string>{"a:=1", "b:=2", "a:=3"}));
  EXPECT_EQ(t.frames, 6);
}

TEST(FlagParser, ErrorMessages) {
  Tool t;
  EXPECT_EQ(t.Error({"--foo"}), "unknown option '--foo' (see --help)");
  EXPECT_EQ(t.Error({"--foo=1"}), "unknown option '--foo' (see --help)");
  EXPECT_EQ(t.Error({"-x"}), "unknown option '-x' (see --help)");
  EXPECT_EQ(t.Error({"--frames", "3", "--scenes"}), "--scenes needs a value DIR");
  EXPECT_EQ(t.Error({"--quiet=1"}), "--quiet takes no value");
  EXPECT_EQ(t.Error({"--frames", "12abc"}), "--frames expects a positive integer, got '12abc'");
  EXPECT_EQ(t.Error({"--frames", "0"}), "--frames expects a positive integer, got '0'");
  EXPECT_EQ(t.Error({"--seed", "-1"}), "--seed expects a non-negative integer, got '-1'");
  EXPECT_EQ(t.Error({"--ridge", "x"}), "--ridge expects a number in [0, 1], got 'x'");
  EXPECT_EQ(t.Error({"--ridge=2"}), "--ridge expects a number in [0, 1], got '2'");
  EXPECT_EQ(t.Error({"--scale", "nan"}), "--scale expects a number, got 'nan'");
  EXPECT_EQ(t.Error({"--fps", "0"}), "--fps expects a positive number, got '0'");
  EXPECT_EQ(t.Error({"--mode", "rgb"}), "--mode expects one of gbuffer|depth, got 'rgb'");
  EXPECT_EQ(t.Error({"--size", "640"}), "--size expects WxH, got '640'");
  EXPECT_EQ(t.Error({"--size", "0x4"}), "--size expects a positive integer, got '0'");
  EXPECT_EQ(t.Error({"input.obj"}), "unexpected argument 'input.obj' (see --help)");
}

TEST(FlagParser, NumberErrorsAreUsageErrors) {
  Tool t;
  PROBELESS_EXPECT_THROWS_MESSAGE((t.Parse({"--frames", "-2"})), UsageError,
                                  "--frames expects a positive integer, got '-2'");
  EXPECT_EQ(RunMain("tool",
                    [&] {
                      t.Parse({"--frames", "x"});
                      return 0;
                    }),
            2);
}

TEST(FlagParser, TruncatedIntTakesAnyNumberWithinTheIntRange) {
  int points = 7;
  FlagParser flags("tool", "");
  flags.AddTruncatedInt("--points", &points, "N", "samples");
  const char* ok[] = {"tool", "--points", "8.9"};
  ASSERT_TRUE(flags.Parse(3, ok));
  EXPECT_EQ(points, 8);
  const char* negative[] = {"tool", "--points=-3.5"};
  ASSERT_TRUE(flags.Parse(2, negative));
  EXPECT_EQ(points, -3);
  const char* huge[] = {"tool", "--points", "1e10"};
  PROBELESS_EXPECT_THROWS_MESSAGE(flags.Parse(3, huge), UsageError,
                                  "--points expects a number in the int range, got '1e10'");
  EXPECT_EQ(points, -3);
}

TEST(FlagParser, OtherExceptionsOfACallbackPropagate) {
  FlagParser flags("tool", "");
  flags.AddCallback("--backend", "NAME", "detector",
                    [](const std::string&) { throw std::runtime_error("no such backend"); });
  const char* argv[] = {"tool", "--backend", "x"};
  PROBELESS_EXPECT_THROWS_MESSAGE(flags.Parse(3, argv), std::runtime_error, "no such backend");
}

TEST(FlagParser, Positionals) {
  std::string input, output;
  std::vector<std::string> rest;
  bool quiet = false;
  FlagParser flags("tool", "");
  flags.Add("--quiet", &quiet, "");
  flags.AddPositional("IN", &input, "input mesh");
  flags.AddPositional("OUT", &output, "output");
  flags.AddPositionals("EXTRA", &rest, "more");
  const char* argv[] = {"tool", "a", "--quiet", "b", "c", "-", "d"};
  EXPECT_TRUE(flags.Parse(7, argv));
  EXPECT_EQ(input, "a");
  EXPECT_EQ(output, "b");
  EXPECT_EQ(rest, (std::vector<std::string>{"c", "-", "d"}));  // "-" (stdin) is an argument
  EXPECT_TRUE(quiet);
  EXPECT_TRUE(flags.Given("IN"));

  std::string only;
  FlagParser one("tool", "");
  one.AddPositional("LOG", &only, "the log");
  const char* two[] = {"tool", "x.mcap", "y.mcap"};
  PROBELESS_EXPECT_THROWS_MESSAGE(one.Parse(3, two), UsageError,
                                  "unexpected argument 'y.mcap' (see --help)");
}

TEST(FlagParser, HelpPrintsTheUsageAndReturnsFalse) {
  for (const char* help : {"--help", "-h"}) {
    Tool t;
    bool parsed = true;
    // Flags before --help are applied, the rest (even malformed) is not read.
    const std::string out = CaptureStdout([&] {
      parsed = t.Parse({"--frames", "3", help, "--foo", "--frames=x"});
    });
    EXPECT_FALSE(parsed);
    EXPECT_EQ(t.frames, 3);
    EXPECT_EQ(out, t.flags.Usage());
  }
}

TEST(FlagParser, UsageListsFlagsMetavarsHelpAndDefaults) {
  Tool t;
  const std::string usage = t.flags.Usage();
  EXPECT_EQ(usage.rfind("usage: tool [options]\ndoes one thing well\n\noptions:\n", 0), 0u)
      << usage;
  EXPECT_THAT(usage, HasSubstr(Line("--scenes DIR", "scene folders (default: eval-world/test)")));
  EXPECT_THAT(usage, HasSubstr(Line("--json OUT", "write the figures here")));
  EXPECT_THAT(usage, HasSubstr(Line("--quiet", "no progress lines")));
  EXPECT_THAT(usage, HasSubstr(Line("--no-flow", "without flow tracking")));
  EXPECT_THAT(usage, HasSubstr(Line("--frames N", "frames to time (default: 200)")));
  EXPECT_THAT(usage, HasSubstr(Line("--seed S", "random seed (default: 7)")));
  EXPECT_THAT(usage, HasSubstr(Line("--ridge X", "regularisation (default: 0.5)")));
  EXPECT_THAT(usage, HasSubstr(Line("--fps F", "frame rate (default: 30)")));
  EXPECT_THAT(usage, HasSubstr(Line("--light-param K:=V", "a scene_light parameter (repeatable)")));
  EXPECT_THAT(usage,
              HasSubstr(Line("--mode gbuffer|depth", "scene_light input (default: gbuffer)")));
  EXPECT_THAT(usage, HasSubstr(Line("--size WxH", "image size (default: 640x480)")));
  EXPECT_THAT(usage, HasSubstr(Line("-h, --help", "print this help and exit")));
}

TEST(FlagParser, UsageNamesPositionalsAndWrapsLongFlags) {
  std::string input;
  std::vector<std::string> rest;
  std::string long_value;
  FlagParser flags("tool", "");
  flags.AddPositional("MESH", &input, "input mesh");
  flags.AddPositionals("FILE", &rest, "more files");
  flags.Add("--a-very-long-flag-name", &long_value, "SOMETHING", "help");
  const std::string usage = flags.Usage();
  EXPECT_EQ(usage.rfind("usage: tool [options] [MESH] [FILE...]\n\narguments:\n  MESH", 0), 0u)
      << usage;
  EXPECT_THAT(usage, HasSubstr("\n  --a-very-long-flag-name SOMETHING\n" + std::string(32, ' ') +
                               "help\n"));
}

TEST(FlagParser, DeclarationMistakesAreLogicErrors) {
  std::string s;
  bool b = false;
  FlagParser flags("tool", "");
  flags.Add("--x", &s, "X", "");
  EXPECT_THROW(flags.Add("--x", &b, ""), std::logic_error);
  EXPECT_THROW(flags.Add("--help", &b, ""), std::logic_error);
  EXPECT_THROW(flags.Add("x", &s, "X", ""), std::logic_error);
  EXPECT_THROW(flags.Add("--y", &s, "", ""), std::logic_error);
}

}  // namespace
}  // namespace probeless::node
