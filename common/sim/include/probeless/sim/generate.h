// The evaluation world: randomised, physically based scenes of ordinary rooms and courtyards with
// ground-truth object insertions, written as TUM RGB-D folders plus the insertion contract of
// docs/evaluation.md (insertion.yaml, rgb_inserted/, mask_object/, mask_effect/, truth.json).
// Rendering: raytrace::PathTrace (path tracing, next-event estimation, area and point lamps, sun
// and sky). Reference: docs/sim.md, section "Generated scenes".
//
// World frame: metres, y up. Camera poses (groundtruth.txt) are camera -> world in the optical
// frame (x right, y down, z forward), the convention of dataset::OpenDataset's "tum" kind.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "probeless/raytrace/geometry.h"
#include "probeless/raytrace/render.h"
#include "probeless/raytrace/scene.h"
#include "probeless/sim/scenario.h"

namespace probeless::sim {

// Disjoint seed ranges: scene k of `--seed S` in a split has the scene seed
// SplitSeedBase(split) + S + k, and S + k must stay below kSplitSeedStride.
enum class Split { kTrain, kValidation, kTest };
inline constexpr uint64_t kSplitSeedStride = 1'000'000;
uint64_t SplitSeedBase(Split split);
// "train", "validation", "test" -> Split; throws ScenarioError "--split: expected train,
// validation or test, got '<text>'" otherwise.
Split ParseSplit(const std::string& text);
std::string SplitName(Split split);

// An object placed in the scene (a box, sphere, cylinder or the procedural head bust).
struct GeneratedObject {
  std::string name;
  std::string shape;                    // "box", "sphere", "cylinder", "head"
  raytrace::Vec3 size{1, 1, 1};         // box: full edge lengths, metres
  float radius = 0.1f;                  // sphere, cylinder, head (half width), metres
  float height = 0.2f;                  // cylinder, metres
  raytrace::Transform object_to_world;  // the shape's centre and orientation
  raytrace::Material material;
};

// An object of insertion.yaml: a Lambertian sphere or box resting on a real surface.
struct InsertionObject {
  std::string shape;  // "sphere" or "box"
  float radius = 0.09f;
  raytrace::Vec3 size{0.2f, 0.12f, 0.15f};
  raytrace::Vec3 albedo{0.75f, 0.75f, 0.75f};  // linear RGB
  raytrace::Vec3 position;                     // centre, world metres
  std::array<double, 4> rotation{0, 0, 0, 1};  // qx qy qz qw (box)
};

// A randomised scene: everything needed to render it, drawn from its seed alone.
struct GeneratedScene {
  std::string name;  // "<split>_<seed, 7 digits>"
  uint64_t seed = 0;
  std::string room;          // "room" (walls, ceiling, windows) or "courtyard" (open sky)
  std::string light_type;    // "directional", "point", "area" or "mixed" (truth.json)
  raytrace::Vec3 room_size;  // interior width (x), height (y), depth (z), metres
  std::vector<GeneratedObject> objects;
  std::vector<raytrace::DirectionalLight> suns;  // 0 or 1
  std::vector<raytrace::PointLight> point_lights;
  std::vector<raytrace::AreaLight> area_lights;
  std::array<raytrace::Vec3, 9> sky_sh{};  // world-frame SH radiance of the sky (0 indoors
                                           // without windows)
  std::vector<InsertionObject> insertions;
  raytrace::Vec3 support_point;  // where the insertions rest (table top or floor), world
  std::vector<raytrace::Transform> camera_path;  // camera -> world per frame
  raytrace::Camera camera;                       // intrinsics (pose: camera_path)
  SensorSpec sensor;                             // Kinect-like depth noise
};

struct GenerateOptions {
  int frames = 5;                // frames per scene (>= 1; hand-held motion at 30 fps)
  int samples_per_pixel = 8;     // paths per pixel of rgb/ and rgb_inserted/ (>= 1), denoised
  int bounces = 3;               // path-tracing bounces (>= 0)
  int probe_directions = 16384;  // paths of the light probe at the insertion (sh_camera)
  int ratio_samples = 2;         // paths per pixel of the dominant-light-only render
  // Edge-avoiding a-trous denoising of rgb/ and rgb_inserted/ guided by first-hit albedo, normal
  // and depth (Dammertz et al. 2010, SVGF's variance weight), so that few paths per pixel leave
  // the noise of a camera rather than of a path tracer.
  bool denoise = true;
  int width = 640;
  int height = 480;
  int threads = 2;
  // Called after each rendered frame of a scene with (scene index, frame done, frames total).
  std::function<void(int, int, int)> progress;
  // Throws ScenarioError (one line, naming the option) for out-of-range values.
  void Validate() const;
};

// Draws scene `seed` (a scene seed, see SplitSeedBase): deterministic in (seed, options' frame
// count and image size).
GeneratedScene GenerateScene(uint64_t seed, Split split, const GenerateOptions& options);

// Builds the ray-traceable scene: every object, lamp and the sky; with `with_insertions` also the
// insertion objects (ids kInsertionIdBase + k).
inline constexpr uint32_t kInsertionIdBase = 1000;
void BuildScene(const GeneratedScene& scene, bool with_insertions, raytrace::Scene* out);

// What WriteGeneratedScene measured, for progress lines and tests.
struct GeneratedSceneSummary {
  std::string folder;
  int frames = 0;
  double exposure = 1;            // fixed for the scene: linear image = exposure * radiance
  int frames_object_visible = 0;  // frames whose mask_object is not empty
  double seconds = 0;
};

// Renders `scene` and writes its folder `out_dir`/<scene.name>/: rgb.txt, depth.txt,
// groundtruth.txt, camera_info.yaml, rgb/, depth/ (16-bit, 5000 units per metre, Kinect-like
// noise), insertion.yaml, rgb_inserted/, mask_object/, mask_effect/, truth.json and scene.json
// (the scene's parameters). Same scene and options -> the same bytes. Throws ScenarioError when a
// file cannot be written.
GeneratedSceneSummary WriteGeneratedScene(const GeneratedScene& scene,
                                          const GenerateOptions& options,
                                          const std::string& out_dir, int scene_index = 0);

}  // namespace probeless::sim
