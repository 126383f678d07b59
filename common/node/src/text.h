// Internal: the small text helpers the node runtime's messages share (flags.cpp, node.cpp).
#pragma once

#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

namespace probeless::node::internal {

// items joined by separator: Join({"a", "b"}, "|") == "a|b".
inline std::string Join(const std::vector<std::string>& items, std::string_view separator) {
  std::string out;
  for (const auto& item : items) {
    if (!out.empty()) out += separator;
    out += item;
  }
  return out;
}

// A real as printf's %g writes it: 0.004, 1, 1e+06, inf, -inf.
inline std::string FormatReal(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", value);
  return text;
}

}  // namespace probeless::node::internal
