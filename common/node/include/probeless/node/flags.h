// The command-line flags of the tools: one small parser instead of a hand-rolled argv loop in
// every tool (issue #21). Nodes take their parameters through node::Node (--ros-args); tools
// declare their flags here, bound to variables, and run under node::RunMain:
//
//   int Run(int argc, char** argv) {
//     int frames = 200;
//     bool json = false;
//     std::string cache;
//     node::FlagParser flags("face_track_bench", "milliseconds per frame of the face tracker");
//     flags.Add("--frames", &frames, "N", "frames to time", 10);  // an integer >= 10
//     flags.Add("--cache", &cache, "DIR", "rendered frames are cached here");
//     flags.Add("--json", &json, "one JSON object instead of a table");
//     if (!flags.Parse(argc, argv)) return 0;  // --help printed the usage
//     ...
//   }
//   int main(int argc, char** argv) {
//     return node::RunMain("face_track_bench", [&] { return Run(argc, argv); });
//   }
//
// Grammar: a flag with a value is written "--x VALUE" or "--x=VALUE" (the name ends at the first
// '='; the next argument is the value whatever it looks like, so "--offset -3" works); a switch is
// "--x" alone; "-h" and "--help" print the usage; anything not starting with '-', and "-" itself,
// is a positional argument (when the tool declares some). Flags may come in any order and be
// repeated: the last value wins, except for repeatable flags (a std::vector target), which collect
// every value in order.
//
// Errors: every malformed command line throws UsageError (exit code 2 through RunMain) with one
// line naming the flag: "unknown option '--foo' (see --help)", "--scenes needs a value DIR",
// "--json takes no value", "--frames expects a positive integer, got '12abc'" (numbers: the words
// of parse::ParseInteger / parse::ParseDouble, ranges included), "--mode expects one of
// gbuffer|depth, got 'x'", "unexpected argument 'x' (see --help)". Exceptions thrown by a tool's
// own callback propagate unchanged, except parse::NumberError, which becomes a UsageError with the
// same message. Declaring a flag twice or with a name not starting with '-' is a bug of the tool:
// std::logic_error.
#pragma once

#include <concepts>
#include <functional>
#include <limits>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "probeless/node/main.h"
#include "probeless/parse/number.h"

namespace probeless::node {

// A tool's flags and positional arguments, bound to variables that keep their value when the flag
// is not given (that value, when not empty, is shown as the default in the usage; switches show
// none). Declare everything, then Parse once. Not thread-safe; the bound variables must outlive
// Parse.
class FlagParser {
 public:
  // `program` is the name in the usage line ("usage: <program> [options] ..."); `description`
  // one line (or a few, '\n'-separated) printed under it.
  FlagParser(std::string program, std::string description);

  // A flag with a text value: "--scenes DIR" stores DIR in *value. `metavar` names the value in
  // the usage and in "needs a value" errors.
  void Add(std::string name, std::string* value, std::string metavar, std::string help);

  // A switch (no value): "--json" sets *value to true.
  void Add(std::string name, bool* value, std::string help);

  // An integer flag: "--frames N" stores N, parsed by parse::ParseInteger<T> in [min, max]
  // (inclusive; defaults: T's whole range). Its error wording applies ("--frames expects a
  // positive integer, got '0'"), thrown as UsageError.
  template <std::integral T>
  requires(!std::same_as<T, bool>) void Add(
      std::string name, T* value, std::string metavar, std::string help,
      std::type_identity_t<T> min = std::numeric_limits<T>::min(),
      std::type_identity_t<T> max = std::numeric_limits<T>::max()) {
    auto set = [=, flag = name](const std::string& text) {
      *value = parse::ParseInteger<T>(flag, text, min, max);
    };
    AddValue(std::move(name), std::move(metavar), std::move(help), std::to_string(*value),
             std::move(set));
  }

  // A real flag: "--ridge X" stores X, parsed by parse::ParseDouble in [min, max] (inclusive):
  // "--ridge expects a number in [0, 1], got '2'", thrown as UsageError.
  void Add(std::string name, double* value, std::string metavar, std::string help,
           double min = std::numeric_limits<double>::lowest(),
           double max = std::numeric_limits<double>::max());

  // A real flag that must be > 0 (a rate, a scale): parse::ParsePositiveDouble, "--fps expects a
  // positive number, got '0'", thrown as UsageError.
  void AddPositive(std::string name, double* value, std::string metavar, std::string help);

  // The same for a float target (parse::ParseFloat: values beyond float's range are refused).
  void Add(std::string name, float* value, std::string metavar, std::string help,
           float min = std::numeric_limits<float>::lowest(),
           float max = std::numeric_limits<float>::max());

  // A repeatable flag: every "--light-param k:=v" appends its value to *values, in order (values
  // already in the vector are kept: they are the defaults).
  void Add(std::string name, std::vector<std::string>* values, std::string metavar,
           std::string help);

  // A flag whose value must be one of `choices`: "--mode gbuffer|depth". The usage shows the
  // choices as the metavar; any other value throws UsageError
  // "--mode expects one of gbuffer|depth, got 'x'".
  void AddChoice(std::string name, std::string* value, std::vector<std::string> choices,
                 std::string help);

  // A switch that runs `action` when given ("--no-flow": [&] { flow = false; }).
  void AddSwitch(std::string name, std::function<void()> action, std::string help);

  // A flag with a value handed to `on_value` (the tool's own parsing: "--size WxH", two flags
  // sharing one variable). `default_text`, when not empty, is shown as the default.
  void AddCallback(std::string name, std::string metavar, std::string help,
                   std::function<void(const std::string&)> on_value, std::string default_text = "");

  // An integer flag that takes any number and truncates it towards zero ("--points 8.0" -> 8), as
  // the face-light tools always did; a value outside the int range throws UsageError
  // "--points expects a number in the int range, got '1e10'". The default shown is *value.
  void AddTruncatedInt(std::string name, int* value, std::string metavar, std::string help);

  // A positional argument: the first argument not starting with '-' goes into the first declared
  // positional, the next into the second, and so on. Positionals are optional here (a tool checks
  // what it requires after Parse).
  void AddPositional(std::string metavar, std::string* value, std::string help);

  // Every positional argument left after the single ones of AddPositional, in order. Without it
  // (or any positional), a positional argument throws UsageError
  // "unexpected argument 'x' (see --help)".
  void AddPositionals(std::string metavar, std::vector<std::string>* values, std::string help);

  // Parses argv[1..argc): stores each flag's value in its variable as it comes. Returns false
  // after printing the usage to stdout when "-h" or "--help" is met (the caller returns 0), true
  // otherwise. Throws UsageError for a malformed command line (see the top of this file).
  bool Parse(int argc, const char* const* argv);

  // The same for arguments without the program name: a node's own arguments (Node::args(), the
  // ones before --ros-args), so its command line overrides the params read before.
  bool Parse(const std::vector<std::string>& args);

  // Whether flag `name` (or the positional with metavar `name`) was given in the last Parse.
  bool Given(std::string_view name) const;

  // The usage text "--help" prints: "usage: <program> [options] <positionals>", the description,
  // then one line per flag: name, metavar, help and default ("(default: 200)").
  std::string Usage() const;

 private:
  struct Flag {
    std::string name;
    std::string metavar;  // empty for switches
    std::string help;
    std::string default_text;
    std::function<void(const std::string&)> set;  // switches ignore the argument
    bool given = false;
  };
  struct Positional {
    std::string metavar;
    std::string help;
    std::string* value = nullptr;                // single positional
    std::vector<std::string>* values = nullptr;  // the rest
    bool given = false;
  };

  void AddValue(std::string name, std::string metavar, std::string help, std::string default_text,
                std::function<void(const std::string&)> set);
  void AddFlag(Flag flag);
  Flag* Find(std::string_view name);

  std::string program_;
  std::string description_;
  std::vector<Flag> flags_;
  std::vector<Positional> positionals_;
};

}  // namespace probeless::node
