#include "names.h"

#include "probeless/node/node.h"

namespace probeless::node::internal {
namespace {

bool IsTokenChar(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_';
}
bool IsDigit(char c) { return c >= '0' && c <= '9'; }

// Valid absolute name: "/" + tokens of [A-Za-z0-9_] not starting with a digit, single '/'.
bool IsValidAbsoluteName(std::string_view name) {
  if (name.size() < 2 || name.front() != '/' || name.back() == '/') return false;
  bool token_start = true;
  for (size_t i = 1; i < name.size(); ++i) {
    const char c = name[i];
    if (c == '/') {
      if (token_start) return false;  // "//"
      token_start = true;
      continue;
    }
    if (!IsTokenChar(c) || (token_start && IsDigit(c))) return false;
    token_start = false;
  }
  return true;
}

[[noreturn]] void ThrowInvalid(std::string_view name) {
  throw NodeError("invalid topic name '" + std::string(name) +
                  "' (expected segments of letters, digits and '_' not starting with a digit, "
                  "separated by single '/', optionally starting with '/' or '~/')");
}

// Glob match of one token: '*' matches any run of characters.
bool MatchToken(std::string_view pattern, std::string_view token) {
  if (pattern.empty()) return token.empty();
  if (pattern.front() == '*') {
    for (size_t skip = 0; skip <= token.size(); ++skip) {
      if (MatchToken(pattern.substr(1), token.substr(skip))) return true;
    }
    return false;
  }
  return !token.empty() && pattern.front() == token.front() &&
         MatchToken(pattern.substr(1), token.substr(1));
}

bool MatchTokens(const std::vector<std::string>& pattern, size_t p,
                 const std::vector<std::string>& name, size_t n) {
  if (p == pattern.size()) return n == name.size();
  if (pattern[p] == "**") {
    for (size_t k = n; k <= name.size(); ++k) {
      if (MatchTokens(pattern, p + 1, name, k)) return true;
    }
    return false;
  }
  return n < name.size() && MatchToken(pattern[p], name[n]) &&
         MatchTokens(pattern, p + 1, name, n + 1);
}

}  // namespace

bool IsValidNodeName(std::string_view name) {
  if (name.empty() || IsDigit(name.front())) return false;
  for (char c : name) {
    if (!IsTokenChar(c)) return false;
  }
  return true;
}

bool IsValidNamespace(std::string_view ns) { return ns == "/" || IsValidAbsoluteName(ns); }

std::string FullyQualifiedName(std::string_view ns, std::string_view node_name) {
  std::string fqn(ns);
  if (fqn != "/") fqn += '/';
  fqn += node_name;
  return fqn;
}

std::string ExpandTopicName(std::string_view name, std::string_view node_name,
                            std::string_view ns) {
  if (name.empty()) throw NodeError("invalid topic name '': empty");
  // Substitutions.
  std::string text;
  for (size_t i = 0; i < name.size();) {
    if (name[i] != '{') {
      text += name[i++];
      continue;
    }
    const size_t close = name.find('}', i);
    if (close == std::string_view::npos) ThrowInvalid(name);
    const std::string_view key = name.substr(i + 1, close - i - 1);
    const bool followed_by_slash = close + 1 < name.size() && name[close + 1] == '/';
    if (key == "node") {
      text += node_name;
    } else if (key == "ns" || key == "namespace") {
      // The root namespace substitutes as "" before a '/' so "{ns}/x" gives "/x", not "//x".
      text += (ns == "/" && followed_by_slash) ? std::string_view() : ns;
    } else {
      throw NodeError("invalid topic name '" + std::string(name) + "': unknown substitution '{" +
                      std::string(key) + "}' (expected {node}, {ns} or {namespace})");
    }
    i = close + 1;
  }
  std::string expanded;
  if (text.front() == '~') {
    if (text.size() > 1 && text[1] != '/') ThrowInvalid(name);
    expanded = FullyQualifiedName(ns, node_name) + text.substr(1);
  } else if (text.front() == '/') {
    expanded = text;
  } else {
    expanded = (ns == "/" ? std::string("/") : std::string(ns) + "/") + text;
  }
  if (!IsValidAbsoluteName(expanded)) ThrowInvalid(name);
  return expanded;
}

std::vector<std::string> SplitPath(std::string_view path) {
  std::vector<std::string> tokens;
  size_t start = 0;
  while (start <= path.size()) {
    size_t end = path.find('/', start);
    if (end == std::string_view::npos) end = path.size();
    if (end > start) tokens.emplace_back(path.substr(start, end - start));
    start = end + 1;
  }
  return tokens;
}

bool MatchNodePattern(std::string_view pattern, std::string_view fqn) {
  return MatchTokens(SplitPath(pattern), 0, SplitPath(fqn), 0);
}

}  // namespace probeless::node::internal
