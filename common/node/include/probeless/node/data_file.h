// Where a node or tool finds the data files it ships with (models, calibrations): one rule for
// every executable, so that `data/face_light/default_model.txt` works from any working directory
// of a build tree and of an installed prefix.
#pragma once

#include <string>

namespace probeless::node {

// `path` resolved against the places the project's data live, in this order:
//  1. empty, absolute, or existing relative to the working directory: `path` unchanged;
//  2. `<source tree>/<path>` (the tree this binary was configured from);
//  3. `<install prefix>/share/probeless/<path>`.
// The first that exists is returned; when none does, `path` unchanged, so that the loader names
// the path the user gave in its error. Never throws for a missing file.
std::string ResolveDataFile(const std::string& path);

}  // namespace probeless::node
