#include "probeless/parse/number.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <string>
#include <system_error>

namespace probeless::parse {
namespace {

// Digits only, at least one. from_chars accepts a '-' even for unsigned types' callers to
// misread, and a sign followed by nothing; checking the shape first keeps those out.
bool AllDigits(std::string_view s) {
  if (s.empty()) return false;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
  }
  return true;
}

// Drops one leading '+' (from_chars does not take it); "+-1" and "++1" keep theirs and fail.
std::string_view StripPlus(std::string_view text) {
  if (text.size() > 1 && text[0] == '+' && text[1] != '-' && text[1] != '+') {
    text.remove_prefix(1);
  }
  return text;
}

// Whether the text has the shape of a decimal integer ([+-]digits), whatever its value.
bool LooksInteger(std::string_view text) {
  if (!text.empty() && (text[0] == '+' || text[0] == '-')) text.remove_prefix(1);
  return AllDigits(text);
}

std::string Quote(std::string_view text) {
  // The message is one line: control characters (a stray newline from a file) are shown escaped.
  std::string out = "'";
  for (char c : text) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
      char buffer[8];
      std::snprintf(buffer, sizeof(buffer), "\\x%02x", static_cast<unsigned char>(c));
      out += buffer;
    } else {
      out += c;
    }
  }
  return out + "'";
}

[[noreturn]] void Throw(std::string_view name, const std::string& what, std::string_view text) {
  throw NumberError(std::string(name) + " expects " + what + ", got " + Quote(text));
}

std::string Real(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.6g", v);
  return buffer;
}

std::string DescribeRealRange(double min, double max, double lowest, double highest) {
  const bool low = min > lowest;
  const bool high = max < highest;
  if (low && high) return "a number in [" + Real(min) + ", " + Real(max) + "]";
  if (low && min == 0) return "a non-negative number";
  if (low) return "a number >= " + Real(min);
  if (high) return "a number <= " + Real(max);
  return "a number";
}

}  // namespace

namespace internal {

std::optional<int64_t> ParseSigned(std::string_view text, int64_t min, int64_t max) {
  text = StripPlus(text);
  const std::string_view digits = (!text.empty() && text[0] == '-') ? text.substr(1) : text;
  if (!AllDigits(digits)) return std::nullopt;
  int64_t value = 0;
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, value);
  if (ec != std::errc() || ptr != end || value < min || value > max) return std::nullopt;
  return value;
}

std::optional<uint64_t> ParseUnsigned(std::string_view text, uint64_t min, uint64_t max) {
  text = StripPlus(text);
  if (!AllDigits(text)) return std::nullopt;  // a '-' is never an unsigned value
  uint64_t value = 0;
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, value);
  if (ec != std::errc() || ptr != end || value < min || value > max) return std::nullopt;
  return value;
}

void ThrowSigned(std::string_view name, std::string_view text, int64_t min, int64_t max,
                 int64_t type_min, int64_t type_max) {
  std::string what;
  if (max == type_max && min == type_min) {
    what = "an integer";
  } else if (max == type_max && min == 0) {
    what = "a non-negative integer";
  } else if (max == type_max && min == 1) {
    what = "a positive integer";
  } else {
    what = "an integer in [" + std::to_string(min) + ", " + std::to_string(max) + "]";
  }
  // An integer beyond the type itself: say where the type ends, the reason it was refused.
  if (LooksInteger(text) && max == type_max && !ParseSigned(text, type_min, type_max)) {
    const bool negative = text[0] == '-';
    if (negative && min == type_min) {
      what += " down to " + std::to_string(type_min);
    } else if (!negative) {
      what += " up to " + std::to_string(type_max);
    }
  }
  Throw(name, what, text);
}

void ThrowUnsigned(std::string_view name, std::string_view text, uint64_t min, uint64_t max,
                   uint64_t type_max) {
  std::string what;
  if (max == type_max && min == 0) {
    what = "a non-negative integer";
  } else if (max == type_max && min == 1) {
    what = "a positive integer";
  } else {
    what = "an integer in [" + std::to_string(min) + ", " + std::to_string(max) + "]";
  }
  if (max == type_max && text.find('-') == std::string_view::npos && LooksInteger(text) &&
      !ParseUnsigned(text, 0, type_max)) {
    what += " up to " + std::to_string(type_max);
  }
  Throw(name, what, text);
}

std::vector<std::string_view> SplitList(std::string_view name, std::string_view text,
                                        size_t min_count, size_t max_count) {
  std::vector<std::string_view> items;
  size_t start = 0;
  while (true) {
    const size_t comma = text.find(',', start);
    items.push_back(text.substr(start, comma == std::string_view::npos ? comma : comma - start));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  if (items.size() < min_count || items.size() > max_count) {
    const std::string count = min_count == max_count
                                  ? std::to_string(min_count)
                                  : std::to_string(min_count) + " to " + std::to_string(max_count);
    Throw(name, count + " comma-separated numbers", text);
  }
  return items;
}

std::string ItemName(std::string_view name, size_t index) {
  return std::string(name) + " item " + std::to_string(index + 1);
}

}  // namespace internal

std::optional<double> TryParseDouble(std::string_view text, double min, double max) {
  text = StripPlus(text);
  // from_chars also reads "inf", "nan" and "infinity"; only digits, '.', the exponent and a sign
  // may appear in a probeless number.
  if (text.empty()) return std::nullopt;
  for (char c : text) {
    const bool ok =
        (c >= '0' && c <= '9') || c == '.' || c == 'e' || c == 'E' || c == '-' || c == '+';
    if (!ok) return std::nullopt;
  }
  double value = 0;
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, value, std::chars_format::general);
  if (ec != std::errc() || ptr != end || !std::isfinite(value) || value < min || value > max) {
    return std::nullopt;
  }
  return value;
}

double ParseDouble(std::string_view name, std::string_view text, double min, double max) {
  if (const auto v = TryParseDouble(text, min, max)) return *v;
  Throw(name,
        DescribeRealRange(min, max, std::numeric_limits<double>::lowest(),
                          std::numeric_limits<double>::max()),
        text);
}

double ParsePositiveDouble(std::string_view name, std::string_view text) {
  if (const auto v = TryParseDouble(text, 0.0); v && *v > 0) return *v;
  Throw(name, "a positive number", text);
}

float ParseFloat(std::string_view name, std::string_view text, float min, float max) {
  if (const auto v = TryParseDouble(text, min, max)) return static_cast<float>(*v);
  Throw(name,
        DescribeRealRange(min, max, std::numeric_limits<float>::lowest(),
                          std::numeric_limits<float>::max()),
        text);
}

std::vector<double> ParseDoubleList(std::string_view name, std::string_view text, size_t min_count,
                                    size_t max_count, double min, double max) {
  std::vector<double> out;
  const std::vector<std::string_view> items = internal::SplitList(name, text, min_count, max_count);
  for (size_t i = 0; i < items.size(); ++i) {
    out.push_back(ParseDouble(internal::ItemName(name, i), items[i], min, max));
  }
  return out;
}

}  // namespace probeless::parse
