// composite_eval, before the graph runs: the scene folder as an MCAP log the player plays (the TUM
// frames plus the oracle and baseline lights, and a late copy of the depth in depth mode), what
// the tool learns on the way (intrinsics, ground-truth poses, fusion's world), and the meshes the
// renderers load (the objects and a real-scene proxy, in fusion's world frame).
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "probeless/eval/scene_folder.h"
#include "probeless/msgs/camera_info.h"
#include "probeless/rectify/rectify.h"

namespace probeless::composite_eval {

// A rigid transform p_parent = R p_child + t (row-major R).
struct Rigid {
  std::array<double, 9> r = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  std::array<double, 3> t = {0, 0, 0};
  std::array<double, 3> Apply(const std::array<double, 3>& p) const;
  Rigid Inverse() const;
  Rigid Compose(const Rigid& inner) const;  // this * inner
  static Rigid FromQuaternion(double qx, double qy, double qz, double qw,
                              const std::array<double, 3>& t);
};

struct FrameInfo {
  int64_t stamp_ns = 0;
  std::optional<Rigid> camera_to_world;  // ground truth (groundtruth.txt), if any
  bool has_depth = false;
  std::array<double, 3> mean_linear = {0, 0, 0};  // the camera image's mean linear RGB
};

struct SceneInfo {
  msgs::CameraInfo camera_info;  // the first one the source publishes (as played)
  // The pinhole camera the graph works in: camera_info's, or the rectified one (SetCamera).
  double fx = 525, fy = 525, cx = 319.5, cy = 239.5;
  int width = 0, height = 0;
  std::vector<FrameInfo> frames;  // in play order
  // The first depth image (fusion's first frame: its camera frame is fusion's world): as played
  // (millimetres) and, after SetCamera, in metres in the graph's camera (rectified if need be).
  int64_t first_depth_stamp = -1;
  std::vector<uint16_t> first_depth_mm;
  std::vector<float> first_depth_m;
  int oracle_lights = 0;  // frames given an oracle light (truth with sh_camera)
};

// The camera the graph's nodes see behind the rectify node: `rectifier`'s rectified camera (null:
// camera_info as played, no distortion), and the first depth image in it (nearest resampling, the
// node's default). Throws rectify::RectifyError on a depth of another size.
void SetCamera(SceneInfo& info, const rectify::Rectifier* rectifier);

// Writes `mcap_path` from the TUM folder `scene_dir`: every message of the dataset source, and
// after each frame's own messages (log times +1, +2, +3 ns, the frame's header) a copy of its
// depth on /composite_eval/depth (`late_depth`: scene_light's trigger in depth mode, so it starts
// after fusion has published the frame's pose), the oracle light on /composite_eval/light_oracle
// (frames of `truth` with sh_camera) and the baseline light on /composite_eval/light_baseline
// (uniform radiance = the image's mean linear RGB). Throws dataset::DatasetError on bad input.
SceneInfo WriteSceneLog(const std::string& scene_dir, const eval::Truth* truth, bool late_depth,
                        const std::string& mcap_path);

// Fusion's world (the camera frame of the first depth frame) from the ground-truth world: the
// inverse of that frame's ground-truth pose. Throws eval::EvalError when it has none.
Rigid FusionWorldFromTruthWorld(const SceneInfo& info, const std::string& scene);

// Writes object i as an OBJ (vertex colours = albedo, normals) in fusion's world frame.
void WriteObjectObj(const eval::InsertedObject& object, const Rigid& fusion_from_truth,
                    const std::string& path);

// Writes the first depth image as a triangle grid (every `stride`-th pixel, no triangle across a
// depth jump of > 5 %), in fusion's world frame (= that camera's frame): the renderers' scene mesh.
// Returns the number of vertices.
size_t WriteDepthProxyObj(const SceneInfo& info, int stride, const std::string& path);

// Fusion's volume covering the first depth image and the objects (cube edge, minimum corner,
// truncation, depth_max), in fusion's world.
struct VolumeParams {
  double size = 2.0;
  std::array<double, 3> origin = {-1, -1.2, 0.5};
  double truncation = 0.03;
  double depth_max = 4.0;
};
VolumeParams ChooseVolume(const SceneInfo& info, const std::vector<eval::InsertedObject>& objects,
                          const Rigid& fusion_from_truth);

// True when the object's bounding sphere projects (at least partly) into some frame with a
// ground-truth pose, in front of the camera.
bool VisibleInSomeFrame(const SceneInfo& info, const eval::InsertedObject& object);

}  // namespace probeless::composite_eval
