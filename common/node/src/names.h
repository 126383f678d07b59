// Internal: ROS 2 name rules (node names, namespaces, topic expansion, node-name patterns).
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace probeless::node::internal {

// [A-Za-z_][A-Za-z0-9_]*.
bool IsValidNodeName(std::string_view name);
// "/" or "/" followed by node-name-like tokens separated by single '/', no trailing '/'.
bool IsValidNamespace(std::string_view ns);
// "/talker" or "/a/b/talker".
std::string FullyQualifiedName(std::string_view ns, std::string_view node_name);

// Expands a topic name the ROS 2 way for node `node_name` in namespace `ns`: substitutions
// {node}, {ns} and {namespace}; "~" -> the node's fully qualified name; relative names get the
// namespace. Throws NodeError (message without node prefix) if the name is malformed.
std::string ExpandTopicName(std::string_view name, std::string_view node_name, std::string_view ns);

// Whether a params-file node key (absolute, may contain "*" within a token and "**" for any
// number of tokens) matches the fully qualified node name `fqn`.
bool MatchNodePattern(std::string_view pattern, std::string_view fqn);

// Non-empty '/'-separated tokens of `path`.
std::vector<std::string> SplitPath(std::string_view path);

}  // namespace probeless::node::internal
