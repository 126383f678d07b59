// Launch-file substitutions: "$(arg x)", "$(var x)", "$(env X)", "$(env X default)", "$(dirname)".
// Internal to probeless_launch.
#pragma once

#include <functional>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>

#include "probeless/error/error.h"

namespace probeless::launch::internal {

// A substitution problem without location; the parser adds "<file>:<line>:<col>: ".
class SubstitutionError : public InputError {
 public:
  using InputError::InputError;
};

struct SubstitutionContext {
  // Launch configurations (`arg`, `let`, include arguments, command-line overrides).
  const std::map<std::string, std::string>* variables = nullptr;
  // Environment lookup as seen by the launch file (set_env overlay, then the process).
  std::function<std::optional<std::string>(const std::string& name)> get_env;
  // Directory of the current launch file ($(dirname)).
  std::string dirname;
};

// Maximum nesting of substitutions inside substitution arguments.
inline constexpr int kMaxSubstitutionDepth = 8;

// True if `text` contains "$(".
bool ContainsSubstitution(std::string_view text);

// Replaces every substitution in `text`. Arguments of a substitution are separated by blanks, may
// be single-quoted ('a b') and may contain nested substitutions. Throws SubstitutionError.
std::string Substitute(std::string_view text, const SubstitutionContext& context);

}  // namespace probeless::launch::internal
