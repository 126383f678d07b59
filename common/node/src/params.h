// Internal: parameter values, their YAML parsing and ROS 2 params files.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace probeless::node::internal {

// "[]": an empty list, acceptable for any array type.
struct EmptyArray {
  bool operator==(const EmptyArray&) const = default;
};

using ParamValue =
    std::variant<bool, int64_t, double, std::string, std::vector<bool>, std::vector<int64_t>,
                 std::vector<double>, std::vector<std::string>, EmptyArray>;

// ROS 2 type names: "bool", "integer", "double", "string", "bool_array", "integer_array",
// "double_array", "string_array", "empty_array".
std::string_view TypeName(const ParamValue& value);

// Human-readable value: true, 42, 0.5, text, [1, 2], ["a", "b"], [].
std::string FormatValue(const ParamValue& value);

// Parses `text` as a YAML value (the right side of "-p name:=text"). Plain scalars are typed the
// YAML/ROS way (true/false/yes/no/on/off, integers, floats incl. .inf/.nan, else string); quoted
// scalars are strings; flow or block lists of scalars of one type are arrays (integers mixed with
// floats give a double array). Throws NodeError (message without context) otherwise.
ParamValue ParseParamValue(std::string_view text);

// One node entry of a params file: its (absolute) node key and flattened parameters.
struct ParamsFileEntry {
  std::string pattern;  // e.g. "/talker", "/**", "/ns/*"
  bool wildcard = false;
  std::vector<std::pair<std::string, ParamValue>> params;
};

// Reads a ROS 2 params file. Throws NodeError "params file '<path>': ..." on any problem.
std::vector<ParamsFileEntry> ReadParamsFile(const std::string& path);

}  // namespace probeless::node::internal
