#include "substitution.h"

#include <string>
#include <vector>

namespace probeless::launch::internal {
namespace {

// Shortens `text` for an error message.
std::string Excerpt(std::string_view text) {
  constexpr size_t kMax = 60;
  if (text.size() <= kMax) return std::string(text);
  return std::string(text.substr(0, kMax)) + "...";
}

bool IsBlank(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }

bool StartsSubstitution(std::string_view s, size_t i) {
  return i + 1 < s.size() && s[i] == '$' && s[i + 1] == '(';
}

class Substituter {
 public:
  explicit Substituter(const SubstitutionContext& context) : context_(context) {}

  std::string Run(std::string_view text) {
    std::string out;
    size_t i = 0;
    while (i < text.size()) {
      if (StartsSubstitution(text, i)) {
        out += ParseSubstitution(text, i, 1);
      } else {
        out += text[i++];
      }
    }
    return out;
  }

 private:
  // text[i] is at "$("; evaluates the substitution and leaves i after its ')'.
  std::string ParseSubstitution(std::string_view text, size_t& i, int depth) {
    const size_t start = i;
    if (depth > kMaxSubstitutionDepth) {
      throw SubstitutionError("substitutions nested too deeply in '" + Excerpt(text.substr(start)) +
                              "' (expected at most " + std::to_string(kMaxSubstitutionDepth) +
                              " levels)");
    }
    i += 2;
    std::vector<std::string> words;
    while (true) {
      while (i < text.size() && IsBlank(text[i])) ++i;
      if (i >= text.size()) {
        throw SubstitutionError("unterminated substitution '" + Excerpt(text.substr(start)) +
                                "' (expected ')')");
      }
      if (text[i] == ')') {
        ++i;
        break;
      }
      words.push_back(ParseWord(text, i, depth));
    }
    return Evaluate(words, text.substr(start, i - start));
  }

  // One blank-separated argument of a substitution; may contain quotes and nested substitutions.
  std::string ParseWord(std::string_view text, size_t& i, int depth) {
    std::string word;
    while (i < text.size() && !IsBlank(text[i]) && text[i] != ')') {
      if (StartsSubstitution(text, i)) {
        word += ParseSubstitution(text, i, depth + 1);
      } else if (text[i] == '\'') {
        const size_t quote = i++;
        while (i < text.size() && text[i] != '\'') {
          if (StartsSubstitution(text, i)) {
            word += ParseSubstitution(text, i, depth + 1);
          } else {
            word += text[i++];
          }
        }
        if (i >= text.size()) {
          throw SubstitutionError("unterminated quote in substitution argument '" +
                                  Excerpt(text.substr(quote)) + "' (expected a closing ')");
        }
        ++i;
      } else {
        word += text[i++];
      }
    }
    return word;
  }

  std::string Evaluate(const std::vector<std::string>& words, std::string_view whole) {
    if (words.empty()) {
      throw SubstitutionError(
          "empty substitution '$()' (expected $(arg NAME), $(var NAME), "
          "$(env NAME [DEFAULT]) or $(dirname))");
    }
    const std::string& kind = words[0];
    if (kind == "arg" || kind == "var") {
      if (words.size() != 2) {
        throw SubstitutionError("'" + Excerpt(whole) + "' takes one argument (expected $(" + kind +
                                " NAME))");
      }
      const auto found = context_.variables->find(words[1]);
      if (found == context_.variables->end()) {
        std::string known;
        for (const auto& [name, value] : *context_.variables) {
          known += (known.empty() ? "" : ", ") + name;
        }
        throw SubstitutionError("unknown launch argument '" + words[1] + "' in '" + Excerpt(whole) +
                                "' (expected an arg or let declared before use" +
                                (known.empty() ? std::string() : ": " + known) + ")");
      }
      return found->second;
    }
    if (kind == "env") {
      if (words.size() != 2 && words.size() != 3) {
        throw SubstitutionError("'" + Excerpt(whole) +
                                "' takes one or two arguments (expected $(env NAME [DEFAULT]))");
      }
      if (auto value = context_.get_env(words[1])) return *value;
      if (words.size() == 3) return words[2];
      throw SubstitutionError("environment variable '" + words[1] +
                              "' is not set (expected it set" + " or a default: $(env " + words[1] +
                              " DEFAULT))");
    }
    if (kind == "dirname") {
      if (words.size() != 1) {
        throw SubstitutionError("'" + Excerpt(whole) + "' takes no argument (expected $(dirname))");
      }
      return context_.dirname;
    }
    throw SubstitutionError("unknown substitution '" + Excerpt(whole) +
                            "' (expected arg, var, env or dirname)");
  }

  const SubstitutionContext& context_;
};

}  // namespace

bool ContainsSubstitution(std::string_view text) { return text.find("$(") != text.npos; }

std::string Substitute(std::string_view text, const SubstitutionContext& context) {
  if (!ContainsSubstitution(text)) return std::string(text);
  return Substituter(context).Run(text);
}

}  // namespace probeless::launch::internal
