#include "probeless/node/flags.h"

#include <algorithm>
#include <cstdio>
#include <stdexcept>
#include <utility>

#include "text.h"

namespace probeless::node {
namespace {

constexpr size_t kHelpColumn = 30;  // flags longer than this put their help on the next line
constexpr std::string_view kHelpFlags = "-h, --help";

using internal::FormatReal;
using internal::Join;

// One "  <left>  <help>" line of the usage, the help aligned at kHelpColumn.
void AppendLine(std::string& out, const std::string& left, const std::string& help) {
  out += "  " + left;
  if (help.empty()) {
    out += "\n";
    return;
  }
  if (left.size() + 2 < kHelpColumn) {
    out += std::string(kHelpColumn - left.size(), ' ');
  } else {
    out += "\n" + std::string(kHelpColumn + 2, ' ');
  }
  out += help + "\n";
}

}  // namespace

FlagParser::FlagParser(std::string program, std::string description)
    : program_(std::move(program)), description_(std::move(description)) {}

void FlagParser::Add(std::string name, std::string* value, std::string metavar, std::string help) {
  const std::string default_text = *value;
  AddValue(std::move(name), std::move(metavar), std::move(help), default_text,
           [value](const std::string& text) { *value = text; });
}

void FlagParser::Add(std::string name, bool* value, std::string help) {
  AddSwitch(
      std::move(name), [value] { *value = true; }, std::move(help));
}

void FlagParser::Add(std::string name, double* value, std::string metavar, std::string help,
                     double min, double max) {
  auto set = [=, flag = name](const std::string& text) {
    *value = parse::ParseDouble(flag, text, min, max);
  };
  AddValue(std::move(name), std::move(metavar), std::move(help), FormatReal(*value),
           std::move(set));
}

void FlagParser::AddPositive(std::string name, double* value, std::string metavar,
                             std::string help) {
  auto set = [=, flag = name](const std::string& text) {
    *value = parse::ParsePositiveDouble(flag, text);
  };
  AddValue(std::move(name), std::move(metavar), std::move(help), FormatReal(*value),
           std::move(set));
}

void FlagParser::Add(std::string name, float* value, std::string metavar, std::string help,
                     float min, float max) {
  auto set = [=, flag = name](const std::string& text) {
    *value = parse::ParseFloat(flag, text, min, max);
  };
  AddValue(std::move(name), std::move(metavar), std::move(help), FormatReal(*value),
           std::move(set));
}

void FlagParser::Add(std::string name, std::vector<std::string>* values, std::string metavar,
                     std::string help) {
  const std::string default_text = Join(*values, " ");
  AddValue(std::move(name), std::move(metavar), std::move(help) + " (repeatable)", default_text,
           [values](const std::string& text) { values->push_back(text); });
}

void FlagParser::AddChoice(std::string name, std::string* value, std::vector<std::string> choices,
                           std::string help) {
  const std::string metavar = Join(choices, "|");
  auto set = [=, flag = name](const std::string& text) {
    if (std::find(choices.begin(), choices.end(), text) == choices.end()) {
      throw UsageError(flag + " expects one of " + metavar + ", got '" + text + "'");
    }
    *value = text;
  };
  AddValue(std::move(name), metavar, std::move(help), *value, std::move(set));
}

void FlagParser::AddSwitch(std::string name, std::function<void()> action, std::string help) {
  AddFlag(Flag{.name = std::move(name),
               .metavar = "",
               .help = std::move(help),
               .default_text = "",
               .set = [action = std::move(action)](const std::string&) { action(); }});
}

void FlagParser::AddCallback(std::string name, std::string metavar, std::string help,
                             std::function<void(const std::string&)> on_value,
                             std::string default_text) {
  AddValue(std::move(name), std::move(metavar), std::move(help), std::move(default_text),
           std::move(on_value));
}

void FlagParser::AddTruncatedInt(std::string name, int* value, std::string metavar,
                                 std::string help) {
  const std::string flag = name;
  AddValue(std::move(name), std::move(metavar), std::move(help), std::to_string(*value),
           [value, flag](const std::string& text) {
             const double v = parse::ParseDouble(flag, text);
             if (!(v > -2147483649.0 && v < 2147483648.0)) {  // static_cast beyond int is undefined
               throw UsageError(flag + " expects a number in the int range, got '" + text + "'");
             }
             *value = static_cast<int>(v);
           });
}

void FlagParser::AddPositional(std::string metavar, std::string* value, std::string help) {
  if (!positionals_.empty() && positionals_.back().values) {
    throw std::logic_error("FlagParser: positional " + metavar + " declared after " +
                           positionals_.back().metavar + "...");
  }
  positionals_.push_back({.metavar = std::move(metavar), .help = std::move(help), .value = value});
}

void FlagParser::AddPositionals(std::string metavar, std::vector<std::string>* values,
                                std::string help) {
  if (!positionals_.empty() && positionals_.back().values) {
    throw std::logic_error("FlagParser: two lists of positionals (" + metavar + ")");
  }
  positionals_.push_back(
      {.metavar = std::move(metavar), .help = std::move(help), .values = values});
}

void FlagParser::AddValue(std::string name, std::string metavar, std::string help,
                          std::string default_text, std::function<void(const std::string&)> set) {
  if (metavar.empty()) throw std::logic_error("FlagParser: " + name + " needs a metavar");
  AddFlag(Flag{.name = std::move(name),
               .metavar = std::move(metavar),
               .help = std::move(help),
               .default_text = std::move(default_text),
               .set = std::move(set)});
}

void FlagParser::AddFlag(Flag flag) {
  if (flag.name.size() < 2 || flag.name[0] != '-' || flag.name.find('=') != std::string::npos) {
    throw std::logic_error("FlagParser: invalid flag name '" + flag.name + "'");
  }
  if (flag.name == "-h" || flag.name == "--help" || Find(flag.name)) {
    throw std::logic_error("FlagParser: flag " + flag.name + " declared twice");
  }
  flags_.push_back(std::move(flag));
}

FlagParser::Flag* FlagParser::Find(std::string_view name) {
  for (auto& flag : flags_) {
    if (flag.name == name) return &flag;
  }
  return nullptr;
}

bool FlagParser::Parse(int argc, const char* const* argv) {
  for (auto& flag : flags_) flag.given = false;
  for (auto& positional : positionals_) positional.given = false;
  size_t next_positional = 0;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "-h" || arg == "--help") {
      std::fputs(Usage().c_str(), stdout);
      std::fflush(stdout);
      return false;
    }
    if (arg.empty() || arg[0] != '-' || arg == "-") {
      if (next_positional >= positionals_.size()) {
        throw UsageError("unexpected argument '" + arg + "' (see --help)");
      }
      Positional& positional = positionals_[next_positional];
      positional.given = true;
      if (positional.values) {
        positional.values->push_back(arg);
      } else {
        *positional.value = arg;
        ++next_positional;
      }
      continue;
    }
    const size_t equals = arg.find('=');
    const std::string name = arg.substr(0, equals);
    Flag* flag = Find(name);
    if (!flag) throw UsageError("unknown option '" + name + "' (see --help)");
    std::string value;
    if (flag->metavar.empty()) {
      if (equals != std::string::npos) throw UsageError(name + " takes no value");
    } else if (equals != std::string::npos) {
      value = arg.substr(equals + 1);
    } else if (i + 1 < argc) {
      value = argv[++i];
    } else {
      throw UsageError(name + " needs a value " + flag->metavar);
    }
    try {
      flag->set(value);
    } catch (const parse::NumberError& e) {
      throw UsageError(e.what());
    }
    flag->given = true;
  }
  return true;
}

bool FlagParser::Parse(const std::vector<std::string>& args) {
  std::vector<const char*> argv{program_.c_str()};
  for (const std::string& arg : args) argv.push_back(arg.c_str());
  return Parse(static_cast<int>(argv.size()), argv.data());
}

bool FlagParser::Given(std::string_view name) const {
  for (const auto& flag : flags_) {
    if (flag.name == name) return flag.given;
  }
  for (const auto& positional : positionals_) {
    if (positional.metavar == name) return positional.given;
  }
  return false;
}

std::string FlagParser::Usage() const {
  std::string out = "usage: " + program_ + " [options]";
  for (const auto& positional : positionals_) {
    out += " [" + positional.metavar + (positional.values ? "...]" : "]");
  }
  out += "\n";
  if (!description_.empty()) out += description_ + "\n";
  if (!positionals_.empty()) {
    out += "\narguments:\n";
    for (const auto& positional : positionals_) {
      AppendLine(out, positional.metavar, positional.help);
    }
  }
  out += "\noptions:\n";
  for (const auto& flag : flags_) {
    std::string left = flag.name;
    if (!flag.metavar.empty()) left += " " + flag.metavar;
    std::string help = flag.help;
    if (!flag.default_text.empty()) {
      help += (help.empty() ? "(default: " : " (default: ") + flag.default_text + ")";
    }
    AppendLine(out, left, help);
  }
  AppendLine(out, std::string(kHelpFlags), "print this help and exit");
  return out;
}

}  // namespace probeless::node
