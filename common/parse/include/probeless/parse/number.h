// The one number parser of probeless: command-line options, node parameters given as text,
// environment knobs and the numbers of text file formats all go through it, so "12abc", "-1" for a
// count and a 20-digit value are rejected the same way everywhere (issue #22).
//
// Rules, for every function here:
//   - the whole text is the number: no leading or trailing spaces, no trailing characters;
//   - decimal only; one optional leading '+' or '-' ('-' never accepted where the range has no
//     negative values, so "-1" is not 2^64 - 1);
//   - integers: digits only (no '.', no exponent); the value must lie in [min, max];
//   - reals: fixed or scientific notation ("1.5", "-2e-3", ".5", "5."); finite only (no "inf",
//     "nan", no hexadecimal); the value must lie in [min, max]. Text beyond double's range is
//     refused: an overflow ("1e400") and an underflow to zero ("1e-400"); denormals are kept.
#pragma once

#include <concepts>
#include <cstdint>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/error/error.h"

namespace probeless::parse {

// A number that does not parse or is out of range: one line naming the input (an option, a
// parameter, a field), what was expected and what was given, e.g.
//   "--chunk-size expects a positive integer, got '12abc'"
//   "--chunk-size expects a positive integer up to 18446744073709551615, got
//    '99999999999999999999'"
// It is an InputError, so node::RunMain exits 2 for it.
class NumberError : public InputError {
 public:
  using InputError::InputError;
};

namespace internal {
// The integer types are handled in the widest type of their signedness.
std::optional<int64_t> ParseSigned(std::string_view text, int64_t min, int64_t max);
std::optional<uint64_t> ParseUnsigned(std::string_view text, uint64_t min, uint64_t max);
[[noreturn]] void ThrowSigned(std::string_view name, std::string_view text, int64_t min,
                              int64_t max, int64_t type_min, int64_t type_max);
[[noreturn]] void ThrowUnsigned(std::string_view name, std::string_view text, uint64_t min,
                                uint64_t max, uint64_t type_max);
// The items of a comma-separated list, checked for their count (see ParseDoubleList).
std::vector<std::string_view> SplitList(std::string_view name, std::string_view text,
                                        size_t min_count, size_t max_count);
std::string ItemName(std::string_view name, size_t index);
}  // namespace internal

// `text` as an integer of type T in [min, max] (defaults: T's whole range), or nothing when it
// breaks a rule above. For readers that word their own errors (file and line).
template <std::integral T>
std::optional<T> TryParseInteger(std::string_view text, T min = std::numeric_limits<T>::min(),
                                 T max = std::numeric_limits<T>::max()) {
  if constexpr (std::is_signed_v<T>) {
    const auto v = internal::ParseSigned(text, min, max);
    if (!v) return std::nullopt;
    return static_cast<T>(*v);
  } else {
    const auto v = internal::ParseUnsigned(text, min, max);
    if (!v) return std::nullopt;
    return static_cast<T>(*v);
  }
}

// `text` as an integer of type T in [min, max]; throws NumberError
// "<name> expects <what>, got '<text>'" where <what> is
//   "an integer" / "a non-negative integer" / "a positive integer" (min = T's minimum, 0, 1 and
//   max = T's maximum), otherwise "an integer in [min, max]"; when the text is an integer outside
//   T's own range the limit is named too: "a positive integer up to 65535".
// `name` is what the user wrote: "--chunk-size", "param 'queue_depth'", "FUSION_EVAL_MAXW".
template <std::integral T>
T ParseInteger(std::string_view name, std::string_view text, T min = std::numeric_limits<T>::min(),
               T max = std::numeric_limits<T>::max()) {
  if (const auto v = TryParseInteger<T>(text, min, max)) return *v;
  if constexpr (std::is_signed_v<T>) {
    internal::ThrowSigned(name, text, min, max, std::numeric_limits<T>::min(),
                          std::numeric_limits<T>::max());
  } else {
    internal::ThrowUnsigned(name, text, min, max, std::numeric_limits<T>::max());
  }
}

// `text` as a finite real in [min, max] (inclusive), or nothing when it breaks a rule above.
std::optional<double> TryParseDouble(std::string_view text,
                                     double min = std::numeric_limits<double>::lowest(),
                                     double max = std::numeric_limits<double>::max());

// `text` as a finite real in [min, max]; throws NumberError "<name> expects <what>, got '<text>'"
// with <what> "a number", "a non-negative number" (min 0), "a number >= 0.5", "a number <= 2" or
// "a number in [0, 1]" (limits printed with up to 6 significant digits).
double ParseDouble(std::string_view name, std::string_view text,
                   double min = std::numeric_limits<double>::lowest(),
                   double max = std::numeric_limits<double>::max());

// `text` as a finite real > 0 (a rate, a scale, a size); throws NumberError
// "<name> expects a positive number, got '<text>'".
double ParsePositiveDouble(std::string_view name, std::string_view text);

// ParseDouble narrowed to float: the range check is done on the double, and a value beyond
// float's range is out of range ("<name> expects a number ..., got '1e39'").
float ParseFloat(std::string_view name, std::string_view text,
                 float min = std::numeric_limits<float>::lowest(),
                 float max = std::numeric_limits<float>::max());

// `text` as comma-separated reals ("X,Y,Z"), between min_count and max_count of them, each in
// [min, max]. Throws NumberError "<name> expects 3 comma-separated numbers, got '1,2'" (or "1 to 2
// comma-separated numbers") for a wrong count, and ParseDouble's message for a bad item, named
// "<name> item <i>" (1-based): "--volume-origin item 2 expects a number, got 'y'".
std::vector<double> ParseDoubleList(std::string_view name, std::string_view text, size_t min_count,
                                    size_t max_count,
                                    double min = std::numeric_limits<double>::lowest(),
                                    double max = std::numeric_limits<double>::max());

// ParseDoubleList for integers of type T (each item as ParseInteger<T>(item name, item, min,
// max)): "FUSION_EVAL_ICP item 3 expects a positive integer, got '-4'".
template <std::integral T>
std::vector<T> ParseIntegerList(std::string_view name, std::string_view text, size_t min_count,
                                size_t max_count, T min = std::numeric_limits<T>::min(),
                                T max = std::numeric_limits<T>::max()) {
  std::vector<T> out;
  const std::vector<std::string_view> items = internal::SplitList(name, text, min_count, max_count);
  for (size_t i = 0; i < items.size(); ++i) {
    out.push_back(ParseInteger<T>(internal::ItemName(name, i), items[i], min, max));
  }
  return out;
}

}  // namespace probeless::parse
