#include "arguments.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "names.h"
#include "probeless/node/main.h"
#include "probeless/node/node.h"
#include "probeless/parse/number.h"

namespace probeless::node::internal {
namespace {

[[noreturn]] void Fail(const std::string& message) { throw NodeError("--ros-args: " + message); }

// Splits "[prefix:]left:=right". Returns false without ":=".
bool SplitRule(const std::string& rule, std::string& prefix, std::string& left,
               std::string& right) {
  const size_t assign = rule.find(":=");
  if (assign == std::string::npos) return false;
  left = rule.substr(0, assign);
  right = rule.substr(assign + 2);
  prefix.clear();
  const size_t colon = left.find(':');
  if (colon != std::string::npos) {
    prefix = left.substr(0, colon);
    left = left.substr(colon + 1);
  }
  return true;
}

bool IsValidParamName(std::string_view name) {
  if (name.empty() || name.front() == '.' || name.back() == '.') return false;
  char previous = 0;
  for (char c : name) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '_' || c == '.';
    if (!ok || (c == '.' && previous == '.')) return false;
    previous = c;
  }
  return true;
}

RemapRule ParseRemap(const std::string& rule) {
  RemapRule r;
  r.text = rule;
  if (!SplitRule(rule, r.node, r.from, r.to) || r.from.empty() || r.to.empty()) {
    Fail("invalid remap rule '" + rule + "' (expected from:=to)");
  }
  if (rule.find(':') < rule.find(":=") && !IsValidNodeName(r.node)) {
    Fail("invalid node name '" + r.node + "' before ':' in remap rule '" + rule + "'");
  }
  if (r.from == "__node" || r.from == "__name") {
    r.from = "__node";
    if (!IsValidNodeName(r.to)) {
      Fail("invalid node name '" + r.to + "' in '" + rule +
           "' (letters, digits and '_', not starting with a digit)");
    }
  } else if (r.from == "__ns") {
    if (!IsValidNamespace(r.to)) {
      Fail("invalid namespace '" + r.to + "' in '" + rule +
           "' (expected an absolute name such as /robot1)");
    }
  } else if (r.from.starts_with("__")) {
    Fail("unknown special name '" + r.from + "' in remap rule '" + rule +
         "' (expected __node or __ns)");
  }
  return r;
}

ParamRule ParseParam(const std::string& rule) {
  ParamRule p;
  std::string text;
  if (!SplitRule(rule, p.node, p.name, text)) {
    Fail("invalid parameter rule '" + rule + "' (expected name:=value)");
  }
  if (rule.find(':') < rule.find(":=") && !IsValidNodeName(p.node)) {
    Fail("invalid node name '" + p.node + "' before ':' in parameter rule '" + rule + "'");
  }
  if (!IsValidParamName(p.name)) {
    Fail("invalid parameter name '" + p.name + "' in '" + rule +
         "' (letters, digits, '_' and single '.')");
  }
  try {
    p.value = ParseParamValue(text);
  } catch (const NodeError& e) {
    Fail("invalid value in parameter rule '" + rule + "': " + e.what());
  }
  return p;
}

LogLevelRule ParseLogLevelRule(const std::string& text) {
  LogLevelRule rule;
  const size_t assign = text.find(":=");
  if (assign == std::string::npos) {
    rule.level = text;
  } else {
    rule.logger = text.substr(0, assign);
    rule.level = text.substr(assign + 2);
  }
  try {
    ParseLogLevel(rule.level);
  } catch (const NodeError& e) {
    Fail(e.what());
  }
  return rule;
}

}  // namespace

ParsedArguments ParseArguments(const std::vector<std::string>& argv) {
  ParsedArguments parsed;
  if (!argv.empty()) parsed.program = argv[0];
  bool ros = false;
  for (size_t i = 1; i < argv.size(); ++i) {
    const std::string& arg = argv[i];
    if (!ros) {
      if (arg == "--ros-args") {
        ros = true;
      } else {
        parsed.own_args.push_back(arg);
      }
      continue;
    }
    if (arg == "--ros-args") continue;
    if (arg == "--") {
      ros = false;
      continue;
    }
    auto operand = [&](std::string_view what) -> const std::string& {
      if (i + 1 >= argv.size()) Fail("'" + arg + "' must be followed by " + std::string(what));
      return argv[++i];
    };
    if (arg == "-r" || arg == "--remap") {
      parsed.remaps.push_back(ParseRemap(operand("a remap rule (from:=to)")));
    } else if (arg == "-p" || arg == "--param") {
      parsed.params.push_back(ParseParam(operand("a parameter rule (name:=value)")));
    } else if (arg == "--params-file") {
      parsed.params_files.push_back(operand("a file path"));
    } else if (arg == "--log-level") {
      parsed.log_levels.push_back(ParseLogLevelRule(operand("a log level")));
    } else {
      Fail("unknown argument '" + arg +
           "' (supported: -r/--remap, -p/--param, --params-file, --log-level, --)");
    }
  }
  return parsed;
}

}  // namespace probeless::node::internal

namespace probeless::node {

double ParseNumberOption(std::string_view option, std::string_view text) {
  // parse::'s rules (whole text, finite); the message is parse::ParseDouble's, the error type
  // stays UsageError for the callers that catch it.
  if (const auto value = parse::TryParseDouble(text)) return *value;
  throw UsageError(std::string(option) + " expects a number, got '" + std::string(text) + "'");
}

}  // namespace probeless::node
