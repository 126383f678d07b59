// The simulator: renders a Scenario frame by frame (probeless_raytrace) with sensor effects and
// ground truth, and exposes it as a dataset::Source (kind "sim") so the player, `probeless bag
// convert` and the sim node share it. Topics, frames and ground-truth meaning: docs/sim.md.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "probeless/dataset/source.h"
#include "probeless/raytrace/render.h"
#include "probeless/raytrace/scene.h"
#include "probeless/sim/scenario.h"

namespace probeless::sim {

// Ground truth of the tracked face in one frame (the scenario object with face: true).
struct FaceTruth {
  bool in_view = false;  // the face origin is in front of the camera and projects into the image
  raytrace::Transform head_pose;  // face frame -> camera frame (msgs::FaceObservation::head_pose)
  // The 68 iBUG landmarks projected to pixels (x right, y down; empty when the face has none,
  // i.e. a mesh face without the procedural head's landmark set). Not tested for occlusion.
  std::vector<std::array<float, 2>> landmarks;
  // Surface samples: pixel colour (linear RGB of the noiseless render, clamped to [0, 1]) and
  // camera-frame unit normal at fixed points of the face mesh; valid = visible in this frame.
  std::vector<raytrace::Vec3> sample_rgb;
  std::vector<raytrace::Vec3> sample_normals;
  std::vector<uint8_t> sample_valid;
};

// One simulated frame.
struct SimFrame {
  uint64_t index = 0;              // 0-based
  double time_s = 0;               // index / fps
  raytrace::Camera camera;         // intrinsics and pose (camera -> world) at time_s
  raytrace::Frame render;          // the noiseless render
  std::vector<uint8_t> rgb;        // rgb8 (sRGB) after exposure and colour noise
  double exposure = 1;             // the factor rgb's linear values got (sensor.exposure, auto)
  std::vector<uint16_t> depth_mm;  // depth16 after range, quantisation, noise, holes
  // Lighting at the camera position in the camera frame (see raytrace::LightingAt), in the scene's
  // radiance; published as /groundtruth/light times `exposure` (msgs::ShLightUnits::kLinear: the
  // image's units).
  raytrace::LightingGroundTruth light;
  // Lighting at the face origin in the camera frame (scenarios with a face object, else zero): the
  // reference for the face pipeline (not published; docs/sim.md).
  raytrace::LightingGroundTruth face_light;
  FaceTruth face;
};

class Simulator {
 public:
  // Builds the scene (loads meshes and textures). `threads` >= 1 render threads. Throws
  // ScenarioError naming the scenario and object for unreadable meshes or textures.
  explicit Simulator(Scenario scenario, int threads = 2);
  ~Simulator();
  Simulator(const Simulator&) = delete;
  Simulator& operator=(const Simulator&) = delete;

  const Scenario& scenario() const { return scenario_; }
  // Renders frame `index` (any order): deterministic in (scenario, index) — the same frame is
  // byte-identical whatever was rendered before and whatever the thread count.
  SimFrame Render(uint64_t index);
  // The scene (positioned at the last rendered frame's time).
  const raytrace::Scene& scene() const { return *scene_; }

 private:
  void PoseAt(double t);
  Scenario scenario_;
  std::unique_ptr<raytrace::Scene> scene_;
  std::unique_ptr<raytrace::ThreadPool> pool_;
  std::vector<int> object_index_;               // scene index per scenario object
  int face_object_ = -1;                        // scenario index of the face object, -1 if none
  std::vector<raytrace::Vec3> face_landmarks_;  // face frame
  std::vector<raytrace::Vec3> face_points_;     // sample points, face frame
  std::vector<raytrace::Vec3> face_normals_;    // sample normals, face frame
};

// How a scenario becomes a stream.
struct SimOptions {
  uint64_t max_frames = 0;               // frames per pass at most (0 = the scenario's `frames`)
  int threads = 2;                       // render threads
  std::string topic_prefix = "/camera";  // <prefix>/image, /depth, /camera_info
  std::string ground_truth_prefix = "/groundtruth";  // <prefix>/pose, /light, /face
  // Called after each rendered frame with (frames done, frames per pass).
  std::function<void(uint64_t, uint64_t)> progress;
};

// The scenario at `path` as a Source of kind "sim": per frame, in this order, camera_info,
// image (rgb8), depth (depth16), pose, and at their rates light (ShLight, camera frame, 3 bands)
// and face (FaceObservation). Log time of frame i = round(i * 1e9 / fps); header.stamp_ns = log
// time, sequence = frame number from 1. Throws ScenarioError.
std::unique_ptr<dataset::Source> OpenSimSource(const std::string& path,
                                               const SimOptions& options = {});
std::unique_ptr<dataset::Source> OpenSimSource(Scenario scenario, const SimOptions& options = {});

}  // namespace probeless::sim
