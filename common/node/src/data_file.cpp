#include "probeless/node/data_file.h"

#include <filesystem>
#include <system_error>

namespace probeless::node {

std::string ResolveDataFile(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;  // an unreadable directory counts as "not there", not as an error
  if (path.empty() || fs::path(path).is_absolute() || fs::exists(path, ec)) return path;
  for (const char* base : {PROBELESS_SOURCE_TREE, PROBELESS_INSTALL_DATA}) {
    const fs::path candidate = fs::path(base) / path;
    if (fs::exists(candidate, ec)) return candidate.string();
  }
  return path;
}

}  // namespace probeless::node
