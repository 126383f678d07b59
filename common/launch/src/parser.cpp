// YAML launch file parser: walks the `launch:` action list with a scope (launch configurations,
// set_env overlay, namespace) and produces resolved NodeSpecs.
#include <sys/stat.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "probeless/launch/launch.h"
#include "probeless/parse/number.h"
#include "substitution.h"

namespace probeless::launch {
namespace {

namespace fs = std::filesystem;
using internal::SubstitutionContext;
using internal::SubstitutionError;

// Nesting of groups (YAML aliases can build cyclic graphs; this bounds the walk).
constexpr int kMaxGroupDepth = 64;
// Nesting of includes.
constexpr int kMaxIncludeDepth = 32;
// Actions processed in total (bounds alias fan-out).
constexpr int kMaxActions = 10000;

// The part of the state that groups and includes scope.
struct Scope {
  std::map<std::string, std::string> variables;
  std::vector<std::pair<std::string, std::string>> environment;  // set_env, in order
  std::string ns = "/";
};

// The launch file being walked.
struct FileContext {
  std::string path;  // as shown in messages
  std::string dir;   // for $(dirname) and relative paths
  int include_depth = 0;
  bool top_level = false;
};

// One key of a YAML mapping.
struct Field {
  std::string key;
  YAML::Node key_node;
  YAML::Node value;
};

std::string Join(const std::vector<std::string>& items, std::string_view separator) {
  std::string out;
  for (const auto& item : items) {
    if (!out.empty()) out += separator;
    out += item;
  }
  return out;
}

// Error messages are one line: control characters from quoted input are escaped.
std::string OneLine(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (c == '\n') {
      out += "\\n";
    } else if (c == '\r') {
      out += "\\r";
    } else if (static_cast<unsigned char>(c) < 0x20 && c != '\t') {
      out += '?';
    } else {
      out += c;
    }
  }
  return out;
}

bool IsIdentifier(std::string_view text) {
  if (text.empty()) return false;
  if (!(std::isalpha(static_cast<unsigned char>(text[0])) || text[0] == '_')) return false;
  return std::all_of(text.begin(), text.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_';
  });
}

// YAML single-quoted scalar text for `text`.
std::string SingleQuote(std::string_view text) {
  std::string out = "'";
  for (char c : text) {
    if (c == '\'') out += '\'';
    out += c;
  }
  return out + "'";
}

bool IsExecutableFile(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode) && ::access(path.c_str(), X_OK) == 0;
}

std::optional<std::string> ReadDiskFile(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return std::nullopt;
  std::ifstream in(path, std::ios::binary);
  if (!in) return std::nullopt;
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) return std::nullopt;
  return text.str();
}

bool DiskFileExists(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

std::optional<std::string> ProcessEnv(const std::string& name) {
  const char* value = std::getenv(name.c_str());
  if (value == nullptr) return std::nullopt;
  return std::string(value);
}

class Parser {
 public:
  explicit Parser(const ParseOptions& options) : options_(options) {
    if (!options_.read_file) options_.read_file = ReadDiskFile;
    if (!options_.file_exists) options_.file_exists = DiskFileExists;
    if (!options_.get_env) options_.get_env = ProcessEnv;
  }

  LaunchDescription Run(std::string_view text, const std::string& file_name) {
    Scope scope;
    for (const auto& [name, value] : options_.arguments) {
      if (!IsIdentifier(name)) {
        throw LaunchError(file_name + ":1:1: invalid launch argument name '" + name +
                          "' given on the command line (expected letters, digits and '_')");
      }
      scope.variables[name] = value;
    }
    FileContext file;
    file.path = file_name;
    file.dir = DirectoryOf(file_name);
    file.top_level = true;
    include_stack_.push_back(fs::path(file_name).lexically_normal().string());
    ParseFile(text, file, scope);
    for (const auto& [name, value] : options_.arguments) {
      if (declared_arguments_.count(name) == 0) {
        std::vector<std::string> known(declared_arguments_.begin(), declared_arguments_.end());
        throw LaunchError(file_name + ":1:1: unknown launch argument '" + name +
                          "' given on the command line (expected one of the declared arguments" +
                          (known.empty() ? std::string(": none") : ": " + Join(known, ", ")) + ")");
      }
    }
    return std::move(result_);
  }

 private:
  static std::string DirectoryOf(const std::string& file) {
    std::string dir = fs::path(file).parent_path().string();
    return dir.empty() ? "." : dir;
  }

  [[noreturn]] static void Fail(const FileContext& file, const YAML::Mark& mark,
                                const std::string& message) {
    const int line = mark.is_null() ? 1 : mark.line + 1;
    const int column = mark.is_null() ? 1 : mark.column + 1;
    throw LaunchError(OneLine(file.path + ":" + std::to_string(line) + ":" +
                              std::to_string(column) + ": " + message));
  }

  [[noreturn]] static void Fail(const FileContext& file, const YAML::Node& at,
                                const std::string& message) {
    Fail(file, at.Mark(), message);
  }

  void ParseFile(std::string_view text, const FileContext& file, Scope& scope) {
    YAML::Node root;
    try {
      root = YAML::Load(std::string(text));
    } catch (const YAML::Exception& e) {
      Fail(file, e.mark, "YAML syntax error: " + e.msg + " (expected valid YAML)");
    }
    try {
      if (!root.IsMap()) {
        Fail(file, root,
             "a launch file must be a mapping with a 'launch' list (expected 'launch:')");
      }
      std::vector<Field> fields = GetFields(file, root, "launch file", {"launch"});
      const Field* launch = Find(fields, "launch");
      if (launch == nullptr) {
        Fail(file, root,
             "launch file has no 'launch' key (expected 'launch:' with a list of actions)");
      }
      ParseActionList(launch->value, file, scope, 0);
    } catch (const YAML::Exception& e) {
      // Defensive: yaml-cpp accessors are used only on checked node types.
      Fail(file, e.mark, "YAML error: " + e.msg + " (expected a well-formed launch file)");
    }
  }

  // Checks that `map` is a mapping whose keys are unique scalars from `allowed`.
  std::vector<Field> GetFields(const FileContext& file, const YAML::Node& map,
                               const std::string& what,
                               std::initializer_list<std::string_view> allowed) {
    if (!map.IsMap()) {
      Fail(file, map, "'" + what + "' must be a mapping (expected key: value pairs)");
    }
    std::vector<Field> fields;
    for (auto it = map.begin(); it != map.end(); ++it) {
      const YAML::Node key = it->first;  // a copy: it-> yields a temporary
      if (!key.IsScalar()) {
        Fail(file, key, "keys of '" + what + "' must be plain names (expected a scalar key)");
      }
      const std::string name = key.Scalar();
      if (std::find(allowed.begin(), allowed.end(), name) == allowed.end()) {
        std::vector<std::string> names(allowed.begin(), allowed.end());
        std::sort(names.begin(), names.end());
        Fail(file, key,
             "unknown key '" + name + "' in '" + what + "' (expected one of: " + Join(names, ", ") +
                 ")");
      }
      if (Find(fields, name) != nullptr) {
        Fail(file, key, "duplicate key '" + name + "' in '" + what + "' (expected each key once)");
      }
      fields.push_back(Field{name, key, it->second});
    }
    return fields;
  }

  static const Field* Find(const std::vector<Field>& fields, std::string_view key) {
    for (const auto& field : fields) {
      if (field.key == key) return &field;
    }
    return nullptr;
  }

  const Field& Require(const FileContext& file, const YAML::Node& map,
                       const std::vector<Field>& fields, std::string_view key,
                       const std::string& what, const std::string& expected) {
    const Field* field = Find(fields, key);
    if (field == nullptr) {
      Fail(file, map,
           "'" + what + "' is missing '" + std::string(key) + "' (expected " + expected + ")");
    }
    return *field;
  }

  SubstitutionContext MakeContext(const FileContext& file, const Scope& scope) {
    SubstitutionContext context;
    context.variables = &scope.variables;
    context.dirname = file.dir;
    context.get_env = [this, &scope](const std::string& name) -> std::optional<std::string> {
      for (auto it = scope.environment.rbegin(); it != scope.environment.rend(); ++it) {
        if (it->first == name) return it->second;
      }
      return options_.get_env(name);
    };
    return context;
  }

  // The scalar text of `node` with substitutions applied. Null nodes give "".
  std::string Text(const FileContext& file, const Scope& scope, const YAML::Node& node,
                   const std::string& what) {
    if (node.IsNull()) return "";
    if (!node.IsScalar()) {
      Fail(file, node, "'" + what + "' must be a single value (expected a scalar)");
    }
    try {
      return internal::Substitute(node.Scalar(), MakeContext(file, scope));
    } catch (const SubstitutionError& e) {
      Fail(file, node, e.what());
    }
  }

  bool Bool(const FileContext& file, const Scope& scope, const YAML::Node& node,
            const std::string& what) {
    std::string text = Text(file, scope, node, what);
    std::string lower = text;
    std::transform(lower.begin(), lower.end(), lower.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (lower == "true" || lower == "1") return true;
    if (lower == "false" || lower == "0") return false;
    Fail(file, node,
         "invalid boolean '" + text + "' for '" + what + "' (expected true, false, 1 or 0)");
  }

  // Evaluates `if` / `unless` of an action; true if the action runs.
  bool ConditionHolds(const FileContext& file, const Scope& scope,
                      const std::vector<Field>& fields) {
    if (const Field* f = Find(fields, "if"); f != nullptr && !Bool(file, scope, f->value, "if")) {
      return false;
    }
    if (const Field* f = Find(fields, "unless");
        f != nullptr && Bool(file, scope, f->value, "unless")) {
      return false;
    }
    return true;
  }

  // Joins a namespace (relative or absolute) onto `base`; validates the segments.
  std::string JoinNamespace(const FileContext& file, const YAML::Node& at, const std::string& base,
                            const std::string& ns) {
    std::string combined = (!ns.empty() && ns[0] == '/') ? ns : base + "/" + ns;
    std::vector<std::string> segments;
    std::string segment;
    std::istringstream in(combined);
    while (std::getline(in, segment, '/')) {
      if (segment.empty()) continue;
      if (!IsIdentifier(segment)) {
        Fail(file, at,
             "invalid namespace '" + ns +
                 "' (expected segments of letters, digits and '_' separated by '/')");
      }
      segments.push_back(segment);
    }
    return "/" + Join(segments, "/");
  }

  void CountAction(const FileContext& file, const YAML::Node& at) {
    if (++action_count_ > kMaxActions) {
      Fail(file, at, "too many actions (expected at most " + std::to_string(kMaxActions) + ")");
    }
  }

  void ParseActionList(const YAML::Node& list, const FileContext& file, Scope& scope, int depth) {
    if (depth > kMaxGroupDepth) {
      Fail(file, list,
           "groups nested too deeply (expected at most " + std::to_string(kMaxGroupDepth) +
               " levels)");
    }
    if (list.IsNull()) return;  // "launch:" with no actions
    if (!list.IsSequence()) {
      Fail(file, list, "actions must be a list (expected '- <action>: ...' entries)");
    }
    for (auto it = list.begin(); it != list.end(); ++it) {
      ParseAction(*it, file, scope, depth);
    }
  }

  void ParseAction(const YAML::Node& entry, const FileContext& file, Scope& scope, int depth) {
    CountAction(file, entry);
    if (!entry.IsMap() || entry.size() != 1) {
      Fail(file, entry,
           "an action must be a mapping with exactly one key (expected e.g. '- node: {...}')");
    }
    const auto it = entry.begin();
    const YAML::Node key = it->first;  // copies: it-> yields a temporary
    const YAML::Node body = it->second;
    if (!key.IsScalar()) {
      Fail(file, key, "an action name must be a plain name (expected e.g. 'node')");
    }
    const std::string kind = key.Scalar();
    if (body.IsNull()) {
      // yaml-cpp places empty values at the next token; point at the action name instead.
      Fail(file, key, "'" + kind + "' must be a mapping (expected key: value pairs)");
    }
    if (kind == "arg") {
      ParseArg(body, file, scope);
    } else if (kind == "let") {
      ParseLet(body, file, scope);
    } else if (kind == "node") {
      ParseNode(body, file, scope);
    } else if (kind == "include") {
      ParseInclude(body, file, scope);
    } else if (kind == "group") {
      ParseGroup(body, file, scope, depth);
    } else if (kind == "set_env" || kind == "set-env") {
      ParseSetEnv(body, file, scope, kind);
    } else if (kind == "push-ros-namespace" || kind == "push_ros_namespace") {
      ParsePushNamespace(body, file, scope, kind);
    } else {
      Fail(file, key,
           "unknown action '" + kind +
               "' (expected one of: arg, group, include, let, node, "
               "push-ros-namespace, set_env)");
    }
  }

  void ParseArg(const YAML::Node& body, const FileContext& file, Scope& scope) {
    const auto fields =
        GetFields(file, body, "arg", {"name", "default", "description", "if", "unless"});
    const Field& name_field = Require(file, body, fields, "name", "arg", "a name");
    if (!ConditionHolds(file, scope, fields)) return;
    const std::string name = Text(file, scope, name_field.value, "name");
    if (!IsIdentifier(name)) {
      Fail(file, name_field.value,
           "invalid launch argument name '" + name +
               "' (expected letters, digits and '_', not starting with "
               "a digit)");
    }
    if (const Field* d = Find(fields, "description")) Text(file, scope, d->value, "description");
    declared_arguments_.insert(name);
    if (scope.variables.count(name) == 0) {
      const Field* default_field = Find(fields, "default");
      if (default_field == nullptr) {
        Fail(file, body,
             "launch argument '" + name + "' has no value (expected " + name +
                 ":=<value> on the command line, an include arg, or a default)");
      }
      scope.variables[name] = Text(file, scope, default_field->value, "default");
    }
    if (file.top_level) {
      auto& args = result_.arguments;
      auto existing = std::find_if(args.begin(), args.end(),
                                   [&](const auto& arg) { return arg.first == name; });
      if (existing == args.end()) {
        args.emplace_back(name, scope.variables[name]);
      } else {
        existing->second = scope.variables[name];
      }
    }
  }

  void ParseLet(const YAML::Node& body, const FileContext& file, Scope& scope) {
    const auto fields = GetFields(file, body, "let", {"name", "value", "if", "unless"});
    const Field& name_field = Require(file, body, fields, "name", "let", "a name");
    const Field& value_field = Require(file, body, fields, "value", "let", "a value");
    if (!ConditionHolds(file, scope, fields)) return;
    const std::string name = Text(file, scope, name_field.value, "name");
    if (!IsIdentifier(name)) {
      Fail(file, name_field.value,
           "invalid launch argument name '" + name +
               "' (expected letters, digits and '_', not starting with "
               "a digit)");
    }
    scope.variables[name] = Text(file, scope, value_field.value, "value");
  }

  void ParseSetEnv(const YAML::Node& body, const FileContext& file, Scope& scope,
                   const std::string& kind) {
    const auto fields = GetFields(file, body, kind, {"name", "value", "if", "unless"});
    const Field& name_field = Require(file, body, fields, "name", kind, "a variable name");
    const Field& value_field = Require(file, body, fields, "value", kind, "a value");
    if (!ConditionHolds(file, scope, fields)) return;
    const std::string name = Text(file, scope, name_field.value, "name");
    if (name.empty() || name.find('=') != name.npos) {
      Fail(file, name_field.value,
           "invalid environment variable name '" + name +
               "' (expected a non-empty name without '=')");
    }
    scope.environment.emplace_back(name, Text(file, scope, value_field.value, "value"));
  }

  void ParsePushNamespace(const YAML::Node& body, const FileContext& file, Scope& scope,
                          const std::string& kind) {
    YAML::Node ns_node = body;
    if (!body.IsScalar()) {
      const auto fields = GetFields(file, body, kind, {"namespace", "if", "unless"});
      ns_node = Require(file, body, fields, "namespace", kind, "a namespace").value;
      if (!ConditionHolds(file, scope, fields)) return;
    }
    scope.ns = JoinNamespace(file, ns_node, scope.ns, Text(file, scope, ns_node, "namespace"));
  }

  void ParseGroup(const YAML::Node& body, const FileContext& file, Scope& scope, int depth) {
    const auto fields =
        GetFields(file, body, "group", {"namespace", "scoped", "children", "if", "unless"});
    const Field& children = Require(file, body, fields, "children", "group", "a list of actions");
    if (!ConditionHolds(file, scope, fields)) return;
    bool scoped = true;
    if (const Field* f = Find(fields, "scoped")) scoped = Bool(file, scope, f->value, "scoped");
    Scope inner = scope;
    if (const Field* f = Find(fields, "namespace")) {
      inner.ns = JoinNamespace(file, f->value, scope.ns, Text(file, scope, f->value, "namespace"));
    }
    ParseActionList(children.value, file, inner, depth + 1);
    if (!scoped) {
      // Launch configurations and environment leave an unscoped group; namespaces never do.
      scope.variables = std::move(inner.variables);
      scope.environment = std::move(inner.environment);
    }
  }

  void ParseInclude(const YAML::Node& body, const FileContext& file, Scope& scope) {
    const auto fields = GetFields(file, body, "include", {"file", "arg", "if", "unless"});
    const Field& file_field =
        Require(file, body, fields, "file", "include", "the path of a launch file");
    if (!ConditionHolds(file, scope, fields)) return;
    const std::string target = Text(file, scope, file_field.value, "file");
    if (target.empty()) {
      Fail(file, file_field.value, "empty include file (expected the path of a launch file)");
    }
    fs::path path(target);
    if (path.is_relative()) path = fs::path(file.dir) / path;
    const std::string normal = path.lexically_normal().string();

    // Include arguments are evaluated in the including scope, then set in the included one.
    Scope inner = scope;
    if (const Field* args = Find(fields, "arg")) {
      if (!args->value.IsSequence()) {
        Fail(file, args->value,
             "'arg' of include must be a list (expected '- {name: x, value: y}')");
      }
      for (auto it = args->value.begin(); it != args->value.end(); ++it) {
        const auto arg_fields = GetFields(file, *it, "include arg", {"name", "value"});
        const Field& n = Require(file, *it, arg_fields, "name", "include arg", "a name");
        const Field& v = Require(file, *it, arg_fields, "value", "include arg", "a value");
        const std::string name = Text(file, scope, n.value, "name");
        if (!IsIdentifier(name)) {
          Fail(file, n.value,
               "invalid launch argument name '" + name +
                   "' (expected letters, digits and '_', not starting with a "
                   "digit)");
        }
        inner.variables[name] = Text(file, scope, v.value, "value");
      }
    }

    if (std::find(include_stack_.begin(), include_stack_.end(), normal) != include_stack_.end()) {
      std::vector<std::string> chain;
      auto start = std::find(include_stack_.begin(), include_stack_.end(), normal);
      chain.assign(start, include_stack_.end());
      chain.push_back(normal);
      Fail(file, file_field.value,
           "include cycle " + Join(chain, " -> ") + " (expected includes without a cycle)");
    }
    if (file.include_depth + 1 > kMaxIncludeDepth) {
      Fail(file, file_field.value,
           "includes nested too deeply (expected at most " + std::to_string(kMaxIncludeDepth) +
               " levels)");
    }
    std::optional<std::string> text = options_.read_file(normal);
    if (!text) {
      Fail(file, file_field.value,
           "cannot read launch file '" + normal + "' (expected an existing, readable file)");
    }
    FileContext included;
    included.path = normal;
    included.dir = DirectoryOf(normal);
    included.include_depth = file.include_depth + 1;
    included.top_level = false;
    include_stack_.push_back(normal);
    ParseFile(*text, included, inner);
    include_stack_.pop_back();
  }

  // YAML text of a parameter value for "-p name:=value".
  std::string ParameterValue(const FileContext& file, const Scope& scope, const YAML::Node& node,
                             const std::string& name, bool allow_sequence) {
    if (node.IsScalar()) {
      const std::string& raw = node.Scalar();
      if (internal::ContainsSubstitution(raw)) {
        // Like ROS 2: the substituted text is typed by the node's YAML reading; an empty text is
        // the empty string (the node runtime rejects "-p name:=" without a value).
        std::string text = Text(file, scope, node, "value");
        return text.empty() ? "''" : text;
      }
      if (node.Tag() == "!" || node.Tag() == "tag:yaml.org,2002:str") return SingleQuote(raw);
      return raw;
    }
    if (node.IsSequence() && allow_sequence) {
      std::vector<std::string> items;
      for (auto it = node.begin(); it != node.end(); ++it) {
        items.push_back(ParameterValue(file, scope, *it, name, false));
      }
      return "[" + Join(items, ", ") + "]";
    }
    if (node.IsNull()) {
      Fail(file, node, "parameter '" + name + "' has no value (expected a value)");
    }
    Fail(file, node,
         "invalid value of parameter '" + name + "' (expected a scalar or a list of scalars)");
  }

  std::optional<std::string> SearchPath(const std::string& name) {
    const std::optional<std::string> path = options_.get_env("PATH");
    if (!path) return std::nullopt;
    std::istringstream in(*path);
    std::string dir;
    while (std::getline(in, dir, ':')) {
      if (dir.empty()) dir = ".";
      const std::string candidate = (fs::path(dir) / name).string();
      if (IsExecutableFile(candidate)) return fs::absolute(candidate).lexically_normal().string();
    }
    return std::nullopt;
  }

  // bin_dir, then relative to the launch file, then PATH.
  std::optional<std::string> ResolveExecutable(const FileContext& file, const std::string& exec) {
    if (fs::path(exec).is_absolute()) {
      return IsExecutableFile(exec) ? std::optional(exec) : std::nullopt;
    }
    const bool bare = exec.find('/') == exec.npos;
    if (bare && !options_.bin_dir.empty()) {
      const std::string candidate = (fs::path(options_.bin_dir) / exec).string();
      if (IsExecutableFile(candidate)) return fs::absolute(candidate).lexically_normal().string();
    }
    const std::string relative = (fs::path(file.dir) / exec).string();
    if (IsExecutableFile(relative)) return fs::absolute(relative).lexically_normal().string();
    if (bare) return SearchPath(exec);
    return std::nullopt;
  }

  void ParseNode(const YAML::Node& body, const FileContext& file, Scope& scope) {
    const auto fields =
        GetFields(file, body, "node",
                  {"pkg", "exec", "name", "namespace", "args", "param", "remap", "env", "output",
                   "respawn", "respawn_delay", "respawn_max_retries", "required", "on_exit",
                   "launch-prefix", "launch_prefix", "if", "unless"});
    const Field& exec_field = Require(file, body, fields, "exec", "node", "an executable name");
    if (!ConditionHolds(file, scope, fields)) return;

    NodeSpec node;
    node.location = SourceLocation{file.path, body.Mark().line + 1, body.Mark().column + 1};
    if (const Field* f = Find(fields, "pkg")) Text(file, scope, f->value, "pkg");  // ignored

    const std::string exec = Text(file, scope, exec_field.value, "exec");
    if (exec.empty()) Fail(file, exec_field.value, "empty 'exec' (expected an executable name)");

    // Name and namespace.
    if (const Field* f = Find(fields, "name")) {
      node.name = Text(file, scope, f->value, "name");
      if (!IsIdentifier(node.name)) {
        Fail(file, f->value,
             "invalid node name '" + node.name +
                 "' (expected letters, digits and '_', not starting with a digit)");
      }
    } else {
      node.name = fs::path(exec).filename().string();
      for (char& c : node.name) {
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_') c = '_';
      }
      if (node.name.empty() || std::isdigit(static_cast<unsigned char>(node.name[0]))) {
        node.name = "_" + node.name;
      }
    }
    node.node_namespace = scope.ns;
    if (const Field* f = Find(fields, "namespace")) {
      node.node_namespace =
          JoinNamespace(file, f->value, scope.ns, Text(file, scope, f->value, "namespace"));
    }
    node.fully_qualified_name =
        (node.node_namespace == "/" ? "" : node.node_namespace) + "/" + node.name;
    if (auto [it, inserted] = node_locations_.emplace(node.fully_qualified_name, node.location);
        !inserted) {
      Fail(file, body,
           "duplicate node '" + node.fully_qualified_name + "' (expected unique names; " +
               "first declared at " + it->second.file + ":" + std::to_string(it->second.line) +
               ")");
    }

    // Executable.
    if (options_.resolve_executables) {
      std::optional<std::string> resolved = ResolveExecutable(file, exec);
      if (!resolved) {
        std::string where = options_.bin_dir.empty() ? "" : options_.bin_dir + ", ";
        Fail(file, exec_field.value,
             "node '" + node.name + "': executable '" + exec + "' not found (expected it in " +
                 where + "relative to " + file.dir + " or in PATH)");
      }
      node.executable = *resolved;
    } else {
      node.executable = exec;
    }

    if (const Field* f = Find(fields, "args")) {
      const std::string args = Text(file, scope, f->value, "args");
      try {
        node.arguments = SplitShellWords(args);
      } catch (const LaunchError& e) {
        Fail(file, f->value, e.what());
      }
    }

    if (const Field* f = Find(fields, "param")) ParseParams(f->value, file, scope, node);

    if (const Field* f = Find(fields, "remap")) {
      if (!f->value.IsSequence()) {
        Fail(file, f->value, "'remap' must be a list (expected '- {from: a, to: b}')");
      }
      for (auto it = f->value.begin(); it != f->value.end(); ++it) {
        const auto remap_fields = GetFields(file, *it, "remap", {"from", "to"});
        const Field& from = Require(file, *it, remap_fields, "from", "remap", "a name");
        const Field& to = Require(file, *it, remap_fields, "to", "remap", "a name");
        Remap remap{Text(file, scope, from.value, "from"), Text(file, scope, to.value, "to")};
        if (remap.from.empty() || remap.to.empty()) {
          Fail(file, *it, "empty remap name (expected non-empty 'from' and 'to')");
        }
        node.remaps.push_back(std::move(remap));
      }
    }

    node.environment = scope.environment;
    if (const Field* f = Find(fields, "env")) {
      if (!f->value.IsSequence()) {
        Fail(file, f->value, "'env' must be a list (expected '- {name: X, value: y}')");
      }
      for (auto it = f->value.begin(); it != f->value.end(); ++it) {
        const auto env_fields = GetFields(file, *it, "env", {"name", "value"});
        const Field& n = Require(file, *it, env_fields, "name", "env", "a variable name");
        const Field& v = Require(file, *it, env_fields, "value", "env", "a value");
        std::string name = Text(file, scope, n.value, "name");
        if (name.empty() || name.find('=') != name.npos) {
          Fail(file, n.value,
               "invalid environment variable name '" + name +
                   "' (expected a non-empty name without '=')");
        }
        node.environment.emplace_back(std::move(name), Text(file, scope, v.value, "value"));
      }
    }
    node.environment.emplace_back("PROBELESS_NODE_NAME", node.fully_qualified_name);

    if (const Field* f = Find(fields, "output")) {
      const std::string output = Text(file, scope, f->value, "output");
      if (output == "screen") {
        node.output = OutputMode::kScreen;
      } else if (output == "log" || output == "both") {
        node.output = OutputMode::kLog;
      } else {
        Fail(file, f->value, "invalid output '" + output + "' (expected screen, log or both)");
      }
    }

    if (const Field* f = Find(fields, "respawn")) {
      node.respawn = Bool(file, scope, f->value, "respawn");
    }
    if (const Field* f = Find(fields, "respawn_delay")) {
      const std::string text = Text(file, scope, f->value, "respawn_delay");
      const std::optional<double> parsed = parse::TryParseDouble(text, 0, 1e6);
      const double value = parsed.value_or(0);
      if (!parsed) {
        Fail(file, f->value,
             "invalid respawn_delay '" + text + "' (expected a number of seconds >= 0)");
      }
      node.respawn_delay_s = value;
    }
    if (const Field* f = Find(fields, "respawn_max_retries")) {
      const std::string text = Text(file, scope, f->value, "respawn_max_retries");
      const std::optional<long> parsed = parse::TryParseInteger<long>(text, -1, 1000000000);
      const long value = parsed.value_or(0);
      if (!parsed) {
        Fail(file, f->value,
             "invalid respawn_max_retries '" + text +
                 "' (expected an integer >= 0, or -1 for unlimited)");
      }
      node.respawn_max_retries = static_cast<int>(value);
    }
    if (const Field* f = Find(fields, "required")) {
      node.required = Bool(file, scope, f->value, "required");
    }
    if (const Field* f = Find(fields, "on_exit")) {
      const std::string text = Text(file, scope, f->value, "on_exit");
      if (text != "shutdown") {
        Fail(file, f->value, "unsupported on_exit '" + text + "' (expected shutdown)");
      }
      node.required = true;
    }

    const Field* prefix = Find(fields, "launch-prefix");
    if (prefix == nullptr) prefix = Find(fields, "launch_prefix");
    if (prefix != nullptr) {
      const std::string text = Text(file, scope, prefix->value, "launch-prefix");
      try {
        node.prefix = SplitShellWords(text);
      } catch (const LaunchError& e) {
        Fail(file, prefix->value, e.what());
      }
      if (!node.prefix.empty() && options_.resolve_executables) {
        const std::string& program = node.prefix[0];
        std::optional<std::string> resolved;
        if (program.find('/') == program.npos) {
          resolved = SearchPath(program);
        } else {
          fs::path path(program);
          if (path.is_relative()) path = fs::path(file.dir) / path;
          if (IsExecutableFile(path.string())) {
            resolved = fs::absolute(path).lexically_normal().string();
          }
        }
        if (!resolved) {
          Fail(file, prefix->value,
               "node '" + node.name + "': launch-prefix program '" + program +
                   "' not found (expected an executable in PATH or a path)");
        }
        node.prefix[0] = *resolved;
      }
    }

    node.argv = BuildNodeArgv(node);
    result_.nodes.push_back(std::move(node));
  }

  void ParseParams(const YAML::Node& list, const FileContext& file, const Scope& scope,
                   NodeSpec& node) {
    if (!list.IsSequence()) {
      Fail(file, list,
           "'param' must be a list (expected '- {name: x, value: y}' or '- {from: file.yaml}')");
    }
    for (auto it = list.begin(); it != list.end(); ++it) {
      const auto fields = GetFields(file, *it, "param", {"name", "value", "from"});
      if (const Field* from = Find(fields, "from")) {
        if (fields.size() != 1) {
          Fail(file, *it,
               "a 'param' entry has either 'from' or 'name' and 'value' (expected "
               "'{from: file.yaml}' or '{name: x, value: y}')");
        }
        const std::string text = Text(file, scope, from->value, "from");
        if (text.empty()) Fail(file, from->value, "empty parameter file (expected a path)");
        fs::path path(text);
        if (path.is_relative()) path = fs::path(file.dir) / path;
        const std::string absolute = fs::absolute(path).lexically_normal().string();
        if (!options_.file_exists(absolute)) {
          Fail(file, from->value,
               "parameter file '" + absolute + "' not found (expected an existing YAML file)");
        }
        node.param_files.push_back(absolute);
        continue;
      }
      const Field& n = Require(file, *it, fields, "name", "param", "a parameter name");
      const Field& v = Require(file, *it, fields, "value", "param", "a value");
      const std::string name = Text(file, scope, n.value, "name");
      const bool valid_name = !name.empty() && std::all_of(name.begin(), name.end(), [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.';
      });
      if (!valid_name) {
        Fail(file, n.value,
             "invalid parameter name '" + name + "' (expected letters, digits, '_' and '.')");
      }
      node.parameters.push_back(Parameter{name, ParameterValue(file, scope, v.value, name, true)});
    }
  }

  ParseOptions options_;
  LaunchDescription result_;
  std::set<std::string> declared_arguments_;
  std::map<std::string, SourceLocation> node_locations_;
  std::vector<std::string> include_stack_;
  int action_count_ = 0;
};

}  // namespace

LaunchDescription ParseLaunchText(std::string_view text, const std::string& file_name,
                                  const ParseOptions& options) {
  return Parser(options).Run(text, file_name);
}

LaunchDescription LoadLaunchFile(const std::string& path, const ParseOptions& options) {
  const std::string absolute = fs::absolute(fs::path(path)).lexically_normal().string();
  std::optional<std::string> text =
      options.read_file ? options.read_file(absolute) : ReadDiskFile(absolute);
  if (!text) {
    throw LaunchError(absolute +
                      ":1:1: cannot read launch file (expected an existing, readable "
                      "file)");
  }
  return ParseLaunchText(*text, absolute, options);
}

std::vector<std::string> BuildNodeArgv(const NodeSpec& node) {
  std::vector<std::string> argv;
  argv.push_back(node.executable);
  argv.insert(argv.end(), node.arguments.begin(), node.arguments.end());
  argv.insert(argv.end(),
              {"--ros-args", "-r", "__node:=" + node.name, "-r", "__ns:=" + node.node_namespace});
  for (const auto& file : node.param_files) argv.insert(argv.end(), {"--params-file", file});
  for (const auto& p : node.parameters) argv.insert(argv.end(), {"-p", p.name + ":=" + p.value});
  for (const auto& r : node.remaps) argv.insert(argv.end(), {"-r", r.from + ":=" + r.to});
  return argv;
}

std::vector<std::string> SplitShellWords(std::string_view text) {
  std::vector<std::string> words;
  std::string word;
  bool in_word = false;
  size_t i = 0;
  while (i < text.size()) {
    const char c = text[i];
    if (c == ' ' || c == '\t' || c == '\n' || c == '\r') {
      if (in_word) words.push_back(std::move(word));
      word.clear();
      in_word = false;
      ++i;
    } else if (c == '\'') {
      const size_t close = text.find('\'', i + 1);
      if (close == text.npos) {
        throw LaunchError("unterminated single quote in '" + std::string(text) +
                          "' (expected a closing ')");
      }
      word.append(text.substr(i + 1, close - i - 1));
      in_word = true;
      i = close + 1;
    } else if (c == '"') {
      ++i;
      bool closed = false;
      while (i < text.size()) {
        if (text[i] == '"') {
          closed = true;
          ++i;
          break;
        }
        if (text[i] == '\\' && i + 1 < text.size() &&
            std::string_view("\"\\$`").find(text[i + 1]) != std::string_view::npos) {
          word += text[i + 1];
          i += 2;
        } else {
          word += text[i++];
        }
      }
      if (!closed) {
        throw LaunchError("unterminated double quote in '" + std::string(text) +
                          "' (expected a closing \")");
      }
      in_word = true;
    } else if (c == '\\') {
      if (i + 1 < text.size()) word += text[i + 1];
      i += 2;
      in_word = true;
    } else {
      word += c;
      in_word = true;
      ++i;
    }
  }
  if (in_word) words.push_back(std::move(word));
  return words;
}

std::optional<std::pair<std::string, std::string>> ParseArgumentOverride(std::string_view text) {
  const size_t pos = text.find(":=");
  if (pos == text.npos || pos == 0) return std::nullopt;
  return std::pair(std::string(text.substr(0, pos)), std::string(text.substr(pos + 2)));
}

}  // namespace probeless::launch
