#include "params.h"

#include <yaml-cpp/yaml.h>

#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

#include "names.h"
#include "probeless/node/node.h"

namespace probeless::node::internal {
namespace {

struct Null {};
using Scalar = std::variant<bool, int64_t, double, std::string, Null>;

bool OneOf(std::string_view s, std::initializer_list<std::string_view> words) {
  for (std::string_view w : words) {
    if (s == w) return true;
  }
  return false;
}

bool AllDigits(std::string_view s) {
  if (s.empty()) return false;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
  }
  return true;
}

// [-+]?(digits[.digits?]|.digits)([eE][-+]?digits)?
bool LooksLikeFloat(std::string_view s) {
  size_t i = 0;
  if (i < s.size() && (s[i] == '+' || s[i] == '-')) ++i;
  size_t digits = 0;
  while (i < s.size() && s[i] >= '0' && s[i] <= '9') ++i, ++digits;
  bool dot = false;
  if (i < s.size() && s[i] == '.') {
    dot = true;
    ++i;
    while (i < s.size() && s[i] >= '0' && s[i] <= '9') ++i, ++digits;
  }
  if (digits == 0) return false;
  bool exponent = false;
  if (i < s.size() && (s[i] == 'e' || s[i] == 'E')) {
    exponent = true;
    ++i;
    if (i < s.size() && (s[i] == '+' || s[i] == '-')) ++i;
    if (!AllDigits(s.substr(i))) return false;
    i = s.size();
  }
  return i == s.size() && (dot || exponent);
}

Scalar ClassifyPlain(const std::string& s) {
  if (OneOf(s, {"", "~", "null", "Null", "NULL"})) return Null{};
  if (OneOf(s, {"true", "True", "TRUE", "yes", "Yes", "YES", "on", "On", "ON"})) return true;
  if (OneOf(s, {"false", "False", "FALSE", "no", "No", "NO", "off", "Off", "OFF"})) return false;
  const std::string_view unsigned_part =
      (!s.empty() && (s[0] == '-' || s[0] == '+')) ? std::string_view(s).substr(1) : s;
  if (AllDigits(unsigned_part)) {
    int64_t value = 0;
    const char* begin = s.data() + (s[0] == '+' ? 1 : 0);
    const auto [end, ec] = std::from_chars(begin, s.data() + s.size(), value);
    if (ec != std::errc() || end != s.data() + s.size()) {
      throw NodeError("integer " + s + " is out of range");
    }
    return value;
  }
  if (OneOf(unsigned_part, {".inf", ".Inf", ".INF"})) {
    return s[0] == '-' ? -std::numeric_limits<double>::infinity()
                       : std::numeric_limits<double>::infinity();
  }
  if (OneOf(s, {".nan", ".NaN", ".NAN"})) return std::numeric_limits<double>::quiet_NaN();
  if (LooksLikeFloat(s)) {
    double value = 0;
    const char* begin = s.data() + (s[0] == '+' ? 1 : 0);
    const auto [end, ec] = std::from_chars(begin, s.data() + s.size(), value);
    if (ec != std::errc() || end != s.data() + s.size()) {
      throw NodeError("number " + s + " is out of range");
    }
    return value;
  }
  return s;
}

Scalar ConvertScalar(const YAML::Node& node) {
  // yaml-cpp tags plain scalars "?" and quoted ones "!"; an explicit !!str also means string.
  if (node.Tag() == "!" || node.Tag() == "tag:yaml.org,2002:str") return node.Scalar();
  return ClassifyPlain(node.Scalar());
}

std::string_view ScalarTypeName(const Scalar& s) {
  switch (s.index()) {
    case 0:
      return "bool";
    case 1:
      return "integer";
    case 2:
      return "double";
    case 3:
      return "string";
  }
  return "null";
}

ParamValue ConvertList(const YAML::Node& node) {
  std::vector<Scalar> items;
  for (const YAML::Node& element : node) {
    if (!element.IsScalar() && !element.IsNull()) {
      throw NodeError("a list may only contain scalars (no nested lists or mappings)");
    }
    items.push_back(element.IsNull() ? Scalar(Null{}) : ConvertScalar(element));
    if (std::holds_alternative<Null>(items.back())) {
      throw NodeError("a list element is empty (null)");
    }
  }
  if (items.empty()) return EmptyArray{};
  bool all_bool = true, all_int = true, all_number = true, all_string = true;
  for (const Scalar& s : items) {
    all_bool &= std::holds_alternative<bool>(s);
    all_int &= std::holds_alternative<int64_t>(s);
    all_number &= std::holds_alternative<int64_t>(s) || std::holds_alternative<double>(s);
    all_string &= std::holds_alternative<std::string>(s);
  }
  if (all_bool) {
    std::vector<bool> v;
    for (const Scalar& s : items) v.push_back(std::get<bool>(s));
    return v;
  }
  if (all_int) {
    std::vector<int64_t> v;
    for (const Scalar& s : items) v.push_back(std::get<int64_t>(s));
    return v;
  }
  if (all_number) {
    std::vector<double> v;
    for (const Scalar& s : items) {
      v.push_back(std::holds_alternative<double>(s) ? std::get<double>(s)
                                                    : static_cast<double>(std::get<int64_t>(s)));
    }
    return v;
  }
  if (all_string) {
    std::vector<std::string> v;
    for (const Scalar& s : items) v.push_back(std::get<std::string>(s));
    return v;
  }
  std::string kinds;
  for (const Scalar& s : items) {
    const std::string_view kind = ScalarTypeName(s);
    if (kinds.find(kind) == std::string::npos)
      kinds += (kinds.empty() ? "" : " and ") + std::string(kind);
  }
  throw NodeError("a list mixes " + kinds + " elements");
}

ParamValue ConvertValue(const YAML::Node& node) {
  if (node.IsNull() || !node.IsDefined()) throw NodeError("the value is empty");
  if (node.IsMap()) throw NodeError("a mapping is not a parameter value");
  if (node.IsSequence()) return ConvertList(node);
  Scalar s = ConvertScalar(node);
  switch (s.index()) {
    case 0:
      return std::get<bool>(s);
    case 1:
      return std::get<int64_t>(s);
    case 2:
      return std::get<double>(s);
    case 3:
      return std::get<std::string>(std::move(s));
  }
  throw NodeError("the value is empty");
}

std::string FormatDouble(double v) {
  if (std::isnan(v)) return ".nan";
  if (std::isinf(v)) return v > 0 ? ".inf" : "-.inf";
  char buffer[64];
  const auto [end, ec] = std::to_chars(buffer, buffer + sizeof(buffer), v);
  std::string text(buffer, end);
  // Keep doubles recognisable as such ("1" -> "1.0").
  if (text.find_first_of(".en") == std::string::npos) text += ".0";
  return text;
}

template <class T, class F>
std::string FormatList(const std::vector<T>& items, F&& format) {
  std::string text = "[";
  for (size_t i = 0; i < items.size(); ++i) {
    if (i > 0) text += ", ";
    text += format(items[i]);
  }
  return text + "]";
}

std::string Quote(const std::string& s) { return "\"" + s + "\""; }

class ParamsFileReader {
 public:
  explicit ParamsFileReader(std::string path) : path_(std::move(path)) {}

  std::vector<ParamsFileEntry> Read() {
    std::ifstream file(path_);
    if (!file) Fail("cannot open the file");
    std::stringstream text;
    text << file.rdbuf();
    YAML::Node root;
    try {
      root = YAML::Load(text.str());
    } catch (const YAML::Exception& e) {
      Fail("line " + std::to_string(e.mark.line + 1) + ", column " +
           std::to_string(e.mark.column + 1) + ": " + e.msg);
    }
    if (root.IsNull()) return {};
    if (!root.IsMap()) Fail("the top level must map node names to 'ros__parameters'");
    WalkNodes(root, "");
    return std::move(entries_);
  }

 private:
  [[noreturn]] void Fail(const std::string& message) const {
    throw NodeError("params file '" + path_ + "': " + message);
  }

  // `prefix` is the node path so far ("" or "/ns").
  void WalkNodes(const YAML::Node& map, const std::string& prefix) {
    for (const auto& item : map) {
      const std::string key = item.first.as<std::string>();
      if (key == "ros__parameters") {
        if (prefix.empty()) Fail("'ros__parameters' must be under a node name");
        ParamsFileEntry entry;
        entry.pattern = prefix;
        entry.wildcard = prefix.find('*') != std::string::npos;
        if (!item.second.IsNull()) {
          if (!item.second.IsMap()) {
            Fail("'ros__parameters' of '" + prefix + "' must be a mapping");
          }
          Flatten(item.second, "", prefix, entry.params);
        }
        entries_.push_back(std::move(entry));
        continue;
      }
      std::string path = prefix;
      for (const std::string& token : SplitPath(key)) path += "/" + token;
      if (path == prefix) Fail("empty node name key '" + key + "'");
      if (!item.second.IsMap()) {
        Fail("'" + path + "' must be a mapping holding 'ros__parameters' (or nested node names)");
      }
      WalkNodes(item.second, path);
    }
  }

  void Flatten(const YAML::Node& map, const std::string& prefix, const std::string& node,
               std::vector<std::pair<std::string, ParamValue>>& out) {
    for (const auto& item : map) {
      const std::string name = prefix + item.first.as<std::string>();
      if (item.second.IsMap()) {
        Flatten(item.second, name + ".", node, out);
        continue;
      }
      try {
        out.emplace_back(name, ConvertValue(item.second));
      } catch (const NodeError& e) {
        Fail("parameter '" + name + "' of '" + node + "': " + e.what());
      }
    }
  }

  std::string path_;
  std::vector<ParamsFileEntry> entries_;
};

}  // namespace

std::string_view TypeName(const ParamValue& value) {
  static constexpr std::string_view kNames[] = {"bool",         "integer",      "double",
                                                "string",       "bool_array",   "integer_array",
                                                "double_array", "string_array", "empty_array"};
  return kNames[value.index()];
}

std::string FormatValue(const ParamValue& value) {
  struct Visitor {
    std::string operator()(bool v) const { return v ? "true" : "false"; }
    std::string operator()(int64_t v) const { return std::to_string(v); }
    std::string operator()(double v) const { return FormatDouble(v); }
    std::string operator()(const std::string& v) const { return v; }
    std::string operator()(const std::vector<bool>& v) const {
      return FormatList(v, [](bool b) { return std::string(b ? "true" : "false"); });
    }
    std::string operator()(const std::vector<int64_t>& v) const {
      return FormatList(v, [](int64_t i) { return std::to_string(i); });
    }
    std::string operator()(const std::vector<double>& v) const {
      return FormatList(v, FormatDouble);
    }
    std::string operator()(const std::vector<std::string>& v) const { return FormatList(v, Quote); }
    std::string operator()(const EmptyArray&) const { return "[]"; }
  };
  return std::visit(Visitor{}, value);
}

ParamValue ParseParamValue(std::string_view text) {
  YAML::Node node;
  try {
    node = YAML::Load(std::string(text));
  } catch (const YAML::Exception& e) {
    throw NodeError("invalid YAML: " + e.msg);
  }
  return ConvertValue(node);
}

std::vector<ParamsFileEntry> ReadParamsFile(const std::string& path) {
  return ParamsFileReader(path).Read();
}

}  // namespace probeless::node::internal
