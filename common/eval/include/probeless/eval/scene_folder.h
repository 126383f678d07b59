// The files of a composite-evaluation scene folder beyond TUM RGB-D (docs/evaluation.md): the
// objects to insert (insertion.yaml), the true light per frame (truth.json) and the frame list
// (rgb.txt, read here to name the frames' files).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "probeless/error/error.h"

namespace probeless::eval {

// Bad input of the evaluation (malformed or missing scene file): one line naming the file, the
// line where known, the field and what was expected.
class EvalError : public InputError {
 public:
  using InputError::InputError;
};

enum class Shape { kSphere, kBox };

// One object of insertion.yaml, in the world frame of groundtruth.txt.
struct InsertedObject {
  Shape shape = Shape::kSphere;
  double radius = 0;                                  // m (sphere), > 0
  std::array<double, 3> size = {0, 0, 0};             // m, full edge lengths (box), each > 0
  std::array<double, 3> albedo = {0.75, 0.75, 0.75};  // linear RGB in [0, 1]
  std::array<double, 3> position = {0, 0, 0};         // m, the object's centre
  std::array<double, 4> rotation = {0, 0, 0, 1};      // qx qy qz qw, unit (box; sphere ignores it)

  // Radius of the smallest sphere about `position` holding the object.
  double BoundingRadius() const;
};

// Reads an insertion.yaml: a mapping with `objects`, a non-empty list of mappings with `shape`
// (sphere | box), `radius` (sphere) or `size` (box), optional `albedo` (default 0.75 grey),
// `position`, optional `rotation` (normalised). Other keys are ignored. `display` names the file
// in messages (e.g. "kitchen/insertion.yaml"). Throws EvalError
// "<display>:<line>: objects[0].radius: expected a positive number, got 'abc'" (line 1-based).
std::vector<InsertedObject> LoadInsertion(const std::string& path, const std::string& display);

// One frame of truth.json.
struct TruthFrame {
  std::string timestamp;                                  // as written in rgb.txt
  std::optional<std::array<double, 3>> direction_camera;  // unit, scene -> light, optical frame
  double direct_to_ambient = 0;
  // Nine linear SH coefficients [r, g, b] (msgs/sh_light.h convention, camera frame).
  std::optional<std::array<std::array<double, 3>, 9>> sh_camera;
};

struct Truth {
  std::string light_type;  // directional | point | area | mixed (not checked)
  std::vector<TruthFrame> frames;
  // The frame with this rgb.txt time stamp (compared as nanoseconds), or nullptr.
  const TruthFrame* Find(int64_t stamp_ns) const;
};

// Reads truth.json (JSON, read as YAML flow): `light_type`, `frames` (list of `timestamp`,
// `direction_camera` (3 numbers or null), `direct_to_ambient`, optional `sh_camera` of 9
// [r, g, b]). Other keys are ignored. Throws EvalError "<display>:<line>: frames[2].sh_camera:
// expected 9 [r, g, b] coefficients, got 4".
Truth LoadTruth(const std::string& path, const std::string& display);

// One line of rgb.txt.
struct RgbEntry {
  std::string timestamp;  // as written
  int64_t stamp_ns = 0;   // exact decimal conversion (the dataset source's stamps)
  std::string file;       // relative to the folder, e.g. "rgb/1305031102.175304.png"
};

// Reads rgb.txt (`timestamp filename` lines, `#` comments), sorted by time stamp. Throws
// EvalError "<display>:<line>: expected 'timestamp filename', got '...'".
std::vector<RgbEntry> LoadRgbList(const std::string& path, const std::string& display);

// Seconds as decimal text ("1305031102.175304") to nanoseconds, exactly; nullopt if malformed.
std::optional<int64_t> ParseStampNs(const std::string& text);

}  // namespace probeless::eval
