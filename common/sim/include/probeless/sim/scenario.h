// Simulator scenarios: a scene (objects, lights, environment), a camera path, sensor effects and
// ground-truth rates, read from YAML (reference: docs/sim.md). World frame: metres, y up.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "probeless/dataset/source.h"

namespace probeless::sim {

// A malformed scenario: one line "<file>:<line>: <field>: <problem>" (line 1-based). A
// dataset::DatasetError, so the player and `probeless bag convert` report it like other sources.
class ScenarioError : public dataset::DatasetError {
 public:
  using dataset::DatasetError::DatasetError;
};

using Vec3d = std::array<double, 3>;

// A pose keyframe of the camera or an object at time t (seconds). Orientation: `look_at` (camera:
// +z towards it, -y towards `up`) or `rotation_deg` (R = Rz Ry Rx, degrees, object -> world).
struct PoseKey {
  double t = 0;
  Vec3d position{0, 0, 0};
  std::optional<Vec3d> look_at;
  Vec3d up{0, 1, 0};
  Vec3d rotation_deg{0, 0, 0};
};

// A light keyframe: values hold from t on and are interpolated linearly towards the next key
// (`on` switches at the key, no interpolation).
struct LightKey {
  double t = 0;
  Vec3d position{0, 2, 0};              // point lights, world metres
  Vec3d direction{0, 1, 0};             // directional lights, towards the light (normalised on use)
  Vec3d color{1, 1, 1};                 // linear RGB
  double intensity = 3.14159265358979;  // irradiance (directional) or intensity (point) scale
  bool on = true;
};

// A light moving on a circle: position (point light) or direction from `centre` (directional
// light) = centre + radius (cos a, 0, sin a) + (0, height, 0), a = phase + 2 pi t / period.
struct Orbit {
  Vec3d centre{0, 0, 0};
  double radius = 1;
  double height = 0;
  double period_s = 10;
  double phase_deg = 0;
};

struct LightSpec {
  std::string name;
  bool directional = true;     // else point
  std::vector<LightKey> keys;  // >= 1, sorted by t
  std::optional<Orbit> orbit;  // overrides position/direction of the keys
};

struct ObjectSpec {
  std::string name;
  std::string shape;     // "plane", "box", "sphere", "cylinder", "head", "mesh"
  Vec3d size{1, 1, 1};   // box edges; plane x and z (size[0], size[2])
  double radius = 0.5;   // sphere, cylinder
  double height = 1;     // cylinder
  std::string file;      // mesh: resolved path ("" if missing and a fallback applies)
  std::string fallback;  // mesh: "head" = use the procedural head if the file is missing
  double scale = 1;      // mesh: uniform scale applied to the file's coordinates
  Vec3d mesh_rotation_deg{0, 0, 0};  // mesh: rotation (Rz Ry Rx) applied after scale
  Vec3d mesh_offset{0, 0, 0};        // mesh: translation applied after rotation
  Vec3d color{0.7, 0.7, 0.7};        // linear albedo (vertex colours of meshes/heads win)
  std::string texture;               // resolved albedo texture path, "" = none
  double uv_repeat = 1;              // plane texture repeats
  double specular = 0;
  double shininess = 32;
  uint32_t id = 0;            // object-id value (default: 1-based object index)
  bool face = false;          // the tracked face (default true for shape head)
  std::vector<PoseKey> path;  // >= 1 pose keys, sorted by t
};

struct CameraSpec {
  int width = 640;
  int height = 480;
  double fx = 525;
  double fy = 525;
  double cx = 319.5;
  double cy = 239.5;
  std::vector<PoseKey> path;  // >= 1
};

struct RenderSpec {
  bool shadows = true;
  bool diffuse_bounce = false;
  int bounce_samples = 2;
};

// Kinect-like sensor effects (all off by default except the valid depth range).
struct SensorSpec {
  double depth_min_m = 0.4;  // closer returns are invalid (0)
  double depth_max_m = 8.0;  // farther returns are invalid (0)
  bool depth_noise = false;  // Gaussian axial noise, sigma = a + b (z - 0.4)^2 metres
  double depth_noise_a = 0.0012;
  double depth_noise_b = 0.0019;
  bool depth_holes = false;  // invalidate depth edges (neighbour jump > edge_ratio * z)
  double edge_ratio = 0.04;
  double dropout = 0;          // probability of a random invalid depth pixel
  double quantisation = 0;     // disparity quantisation: step = quantisation * z^2 (m; 0 = mm only)
  double color_noise = 0;      // Gaussian sigma on linear RGB
  double exposure = 1;         // fixed exposure multiplier
  bool auto_exposure = false;  // scale so that the mean linear luminance is 0.18 (per frame)
};

struct Scenario {
  std::string path;  // the YAML file
  std::string name;
  uint64_t seed = 1;
  double fps = 30;
  uint64_t frames = 90;
  CameraSpec camera;
  RenderSpec render;
  SensorSpec sensor;
  std::array<Vec3d, 9> environment_sh{};  // world frame, linear RGB
  std::string environment_map;            // resolved lat-long file, "" = none
  double environment_map_scale = 1;
  std::vector<ObjectSpec> objects;
  std::vector<LightSpec> lights;
  double face_rate_hz = 0;   // FaceObservation rate (0 = every frame)
  double light_rate_hz = 0;  // ShLight rate (0 = every frame)
  std::string camera_frame_id = "camera";
  std::string world_frame_id = "world";
};

// Reads a scenario. Relative file names resolve against the YAML file's folder; "data:REL" names
// resolve to $PROBELESS_DATA/REL, else <source tree>/../shared/data/REL. Throws ScenarioError
// ("<file>:<line>: ...") for YAML syntax errors, unknown keys, wrong types or values, and missing
// files (a mesh with `fallback: head` may be missing).
Scenario LoadScenario(const std::string& path);

// The same from YAML text; `name_for_errors` stands for the file in messages and `base_dir` for
// relative file names.
Scenario ParseScenario(const std::string& yaml, const std::string& name_for_errors,
                       const std::string& base_dir);

// Where "data:REL" points: $PROBELESS_DATA/REL if that exists, else <source>/../shared/data/REL;
// nullopt if neither exists.
std::optional<std::string> FindDataFile(const std::string& relative);

}  // namespace probeless::sim
