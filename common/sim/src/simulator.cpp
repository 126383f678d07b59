#include "probeless/sim/simulator.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <deque>
#include <numbers>
#include <optional>

#include "probeless/msgs/camera_info.h"
#include "probeless/msgs/face_observation.h"
#include "probeless/msgs/image.h"
#include "probeless/msgs/pose.h"
#include "probeless/msgs/sh_light.h"
#include "sensor.h"

namespace probeless::sim {
namespace {

using raytrace::Mat3;
using raytrace::Transform;
using raytrace::Vec3;

constexpr double kDeg = std::numbers::pi / 180;

Vec3 ToVec3(const Vec3d& v) {
  return {static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2])};
}
Vec3d Lerp(const Vec3d& a, const Vec3d& b, double s) {
  return {a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s, a[2] + (b[2] - a[2]) * s};
}
Mat3 EulerDeg(const Vec3d& deg) {
  return Mat3::FromEulerZyx(deg[2] * kDeg, deg[1] * kDeg, deg[0] * kDeg);
}

// Index k and weight s of time t between keys[k] and keys[k + 1] (s = 0 at or beyond the ends).
template <class Key>
std::pair<size_t, double> Segment(const std::vector<Key>& keys, double t) {
  if (keys.size() == 1 || t <= keys.front().t) return {0, 0};
  if (t >= keys.back().t) return {keys.size() - 1, 0};
  size_t k = 0;
  while (k + 1 < keys.size() && keys[k + 1].t <= t) ++k;
  return {k, (t - keys[k].t) / (keys[k + 1].t - keys[k].t)};
}

Transform PoseAtTime(const std::vector<PoseKey>& keys, double t) {
  const auto [k, s] = Segment(keys, t);
  const PoseKey& a = keys[k];
  const PoseKey& b = keys[std::min(k + 1, keys.size() - 1)];
  const Vec3d position = Lerp(a.position, b.position, s);
  if (a.look_at) {
    const Vec3d target = Lerp(*a.look_at, b.look_at ? *b.look_at : *a.look_at, s);
    return Transform::LookAt(ToVec3(position), ToVec3(target), ToVec3(Lerp(a.up, b.up, s)));
  }
  Transform out;
  out.rotation = EulerDeg(Lerp(a.rotation_deg, b.rotation_deg, s));
  out.translation = position;
  return out;
}

using internal::Rng;
using internal::SplitMix64;

raytrace::Mesh BuildMesh(const Scenario& scenario, const ObjectSpec& o,
                         std::vector<Vec3>* landmarks) {
  const std::string where = scenario.path + ": object '" + o.name + "'";
  if (o.shape == "plane") {
    return raytrace::MakePlane(static_cast<float>(o.size[0]), static_cast<float>(o.size[2]),
                               static_cast<float>(o.uv_repeat));
  }
  if (o.shape == "box") return raytrace::MakeBox(ToVec3(o.size));
  if (o.shape == "sphere") return raytrace::MakeSphere(static_cast<float>(o.radius), 64);
  if (o.shape == "cylinder") {
    return raytrace::MakeCylinder(static_cast<float>(o.radius), static_cast<float>(o.height), 48);
  }
  if (o.shape == "head" || (o.shape == "mesh" && o.file.empty())) {
    raytrace::HeadModel head = raytrace::MakeHead();
    *landmarks = head.landmarks;
    return std::move(head.mesh);
  }
  raytrace::Mesh mesh;
  try {
    mesh = raytrace::LoadMesh(o.file);
  } catch (const raytrace::RaytraceError& e) {
    throw ScenarioError(where + ": " + e.what());
  }
  mesh.Scale(static_cast<float>(o.scale));
  Transform t;
  t.rotation = EulerDeg(o.mesh_rotation_deg);
  t.translation = o.mesh_offset;
  mesh.TransformBy(t);
  return mesh;
}

}  // namespace

Simulator::Simulator(Scenario scenario, int threads)
    : scenario_(std::move(scenario)),
      scene_(std::make_unique<raytrace::Scene>()),
      pool_(std::make_unique<raytrace::ThreadPool>(std::max(1, threads))) {
  for (int i = 0; i < 9; ++i) scene_->environment().sh[i] = ToVec3(scenario_.environment_sh[i]);
  if (!scenario_.environment_map.empty()) {
    try {
      const raytrace::Texture map = raytrace::LoadTexture(scenario_.environment_map);
      const std::array<Vec3, 9> analytic = scene_->environment().sh;
      scene_->SetEnvironmentMap(map, static_cast<float>(scenario_.environment_map_scale));
      // The map adds to the analytic terms (scaled back so `scale` applies to the map only).
      for (int i = 0; i < 9; ++i) {
        scene_->environment().sh[i] =
            scene_->environment().sh[i] * scene_->environment().scale + analytic[i];
      }
      scene_->environment().scale = 1;
    } catch (const raytrace::RaytraceError& e) {
      throw ScenarioError(scenario_.path + ": environment: " + e.what());
    }
  }
  for (size_t i = 0; i < scenario_.objects.size(); ++i) {
    const ObjectSpec& o = scenario_.objects[i];
    std::vector<Vec3> landmarks;
    raytrace::Mesh mesh = BuildMesh(scenario_, o, &landmarks);
    raytrace::Material material;
    material.albedo = ToVec3(o.color);
    material.specular = static_cast<float>(o.specular);
    material.shininess = static_cast<float>(o.shininess);
    if (!o.texture.empty()) {
      try {
        material.texture = std::make_shared<raytrace::Texture>(raytrace::LoadTexture(o.texture));
      } catch (const raytrace::RaytraceError& e) {
        throw ScenarioError(scenario_.path + ": object '" + o.name + "': " + e.what());
      }
      if (mesh.uvs.empty()) {
        throw ScenarioError(scenario_.path + ": object '" + o.name +
                            "': a texture needs a mesh with texture coordinates");
      }
    }
    if (o.face && face_object_ < 0) {
      face_object_ = static_cast<int>(i);
      face_landmarks_ = landmarks;
      if (mesh.normals.empty()) mesh.ComputeNormals();
      // Sample points: front-facing vertices of the face region, every k-th up to 256.
      std::vector<size_t> candidates;
      for (size_t v = 0; v < mesh.positions.size(); ++v) {
        const Vec3 p = mesh.positions[v];
        if (mesh.normals[v].z < -0.5f && std::abs(p.x) < 0.06f && p.y > -0.04f && p.y < 0.12f &&
            p.z < 0.06f) {
          candidates.push_back(v);
        }
      }
      const size_t step = std::max<size_t>(1, (candidates.size() + 255) / 256);
      for (size_t c = 0; c < candidates.size() && face_points_.size() < 256; c += step) {
        face_points_.push_back(mesh.positions[candidates[c]]);
        face_normals_.push_back(mesh.normals[candidates[c]]);
      }
    }
    try {
      object_index_.push_back(
          scene_->AddObject(std::move(mesh), material, PoseAtTime(o.path, 0), o.id));
    } catch (const raytrace::RaytraceError& e) {
      throw ScenarioError(scenario_.path + ": object '" + o.name + "': " + e.what());
    }
  }
}

Simulator::~Simulator() = default;

void Simulator::PoseAt(double t) {
  for (size_t i = 0; i < scenario_.objects.size(); ++i) {
    const ObjectSpec& o = scenario_.objects[i];
    if (o.path.size() > 1) scene_->SetObjectTransform(object_index_[i], PoseAtTime(o.path, t));
  }
  auto& directional = scene_->directional_lights();
  auto& points = scene_->point_lights();
  directional.clear();
  points.clear();
  for (const LightSpec& l : scenario_.lights) {
    const auto [k, s] = Segment(l.keys, t);
    const LightKey& a = l.keys[k];
    const LightKey& b = l.keys[std::min(k + 1, l.keys.size() - 1)];
    Vec3d position = Lerp(a.position, b.position, s);
    Vec3d direction = Lerp(a.direction, b.direction, s);
    const Vec3 color = ToVec3(Lerp(a.color, b.color, s));
    const float intensity = static_cast<float>(a.intensity + (b.intensity - a.intensity) * s);
    if (l.orbit) {
      const Orbit& o = *l.orbit;
      const double angle = o.phase_deg * kDeg + 2 * std::numbers::pi * t / o.period_s;
      const Vec3d offset{o.radius * std::cos(angle), o.height, o.radius * std::sin(angle)};
      position = {o.centre[0] + offset[0], o.centre[1] + offset[1], o.centre[2] + offset[2]};
      direction = offset;
    }
    if (l.directional) {
      directional.push_back({raytrace::Normalize(ToVec3(direction)), color * intensity, a.on});
    } else {
      points.push_back({ToVec3(position), color * intensity, a.on});
    }
  }
}

SimFrame Simulator::Render(uint64_t index) {
  SimFrame f;
  f.index = index;
  f.time_s = static_cast<double>(index) / scenario_.fps;
  PoseAt(f.time_s);
  scene_->Commit();
  const CameraSpec& c = scenario_.camera;
  f.camera.width = c.width;
  f.camera.height = c.height;
  f.camera.fx = c.fx;
  f.camera.fy = c.fy;
  f.camera.cx = c.cx;
  f.camera.cy = c.cy;
  f.camera.camera_to_world = PoseAtTime(c.path, f.time_s);
  raytrace::RenderOptions options;
  options.shadows = scenario_.render.shadows;
  options.diffuse_bounce = scenario_.render.diffuse_bounce;
  options.bounce_samples = scenario_.render.bounce_samples;
  options.seed = scenario_.seed;
  options.frame_index = index;
  f.render = raytrace::Render(*scene_, f.camera, options, pool_.get());

  // Sensor effects: one deterministic random stream per image row (seeded by scenario seed,
  // frame and row), so results do not depend on the thread count.
  const SensorSpec& sensor = scenario_.sensor;
  const uint64_t frame_seed =
      SplitMix64(scenario_.seed) ^ SplitMix64(index * 0x9E3779B97F4A7C15ull + 17);
  const size_t pixels = static_cast<size_t>(c.width) * c.height;
  double exposure = sensor.exposure;
  if (sensor.auto_exposure) {
    double sum = 0;
    for (size_t p = 0; p < pixels; ++p) {
      const float* v = &f.render.linear_rgb[3 * p];
      sum += 0.2126 * v[0] + 0.7152 * v[1] + 0.0722 * v[2];
    }
    const double mean = sum / static_cast<double>(pixels);
    if (mean > 1e-9) exposure *= 0.18 / mean;
  }
  f.exposure = exposure;
  const bool plain_rgb = exposure == 1 && sensor.color_noise == 0;
  if (plain_rgb) {
    f.rgb = f.render.srgb;
  } else {
    f.rgb.resize(pixels * 3);
  }
  f.depth_mm.assign(pixels, 0);
  const std::vector<float>& z0 = f.render.depth_m;
  pool_->ParallelFor(static_cast<size_t>(c.height), [&](size_t row) {
    const int y = static_cast<int>(row);
    Rng rng(frame_seed ^ SplitMix64(row + 0xD1B54A32D192ED03ull));
    const size_t first = row * static_cast<size_t>(c.width);
    if (!plain_rgb) {
      for (size_t i = first * 3; i < (first + c.width) * 3; ++i) {
        double v = f.render.linear_rgb[i] * exposure;
        if (sensor.color_noise > 0) v += sensor.color_noise * rng.Normal();
        f.rgb[i] = raytrace::LinearToSrgb8(static_cast<float>(v));
      }
    }
    internal::SensorDepthRow(z0.data(), c.width, c.height, y, sensor, rng, &f.depth_mm[first]);
  });

  // Ground truth: light at the camera in the camera frame, and the face (with the light at the
  // face origin, camera frame: what the face pipeline estimates; a near point light seen from the
  // camera and from the face can differ by tens of degrees).
  const Transform& pose = f.camera.camera_to_world;
  const Vec3 eye = ToVec3(pose.translation);
  f.light = raytrace::LightingAt(*scene_, eye, pose.rotation);
  if (face_object_ >= 0) {
    f.face_light = raytrace::LightingAt(
        *scene_, scene_->ObjectTransform(object_index_[face_object_]).Apply({0, 0, 0}),
        pose.rotation);
  }
  if (face_object_ >= 0) {
    const int object = object_index_[face_object_];
    const Transform head = pose.Inverse() * scene_->ObjectTransform(object);
    FaceTruth& face = f.face;
    face.head_pose = head;
    const Vec3 origin = head.Apply({0, 0, 0});
    auto project = [&](Vec3 p) {
      return std::array<float, 2>{static_cast<float>(c.fx * p.x / p.z + c.cx),
                                  static_cast<float>(c.fy * p.y / p.z + c.cy)};
    };
    if (origin.z > 0.05f) {
      const auto uv = project(origin);
      face.in_view =
          uv[0] >= -0.5f && uv[1] >= -0.5f && uv[0] <= c.width - 0.5f && uv[1] <= c.height - 0.5f;
    }
    if (face.in_view) {
      for (const Vec3& l : face_landmarks_) face.landmarks.push_back(project(head.Apply(l)));
      const uint32_t id = scene_->ObjectId(object);
      for (size_t i = 0; i < face_points_.size(); ++i) {
        const Vec3 p = head.Apply(face_points_[i]);
        const Vec3 n = raytrace::Normalize(head.ApplyDirection(face_normals_[i]));
        Vec3 rgb{};
        bool valid = false;
        if (p.z > 0.05f && raytrace::Dot(n, p) < 0) {
          const auto uv = project(p);
          const long u = std::lround(uv[0]);
          const long v = std::lround(uv[1]);
          if (u >= 0 && v >= 0 && u < c.width && v < c.height) {
            const size_t px = static_cast<size_t>(v) * c.width + static_cast<size_t>(u);
            valid = f.render.object_ids[px] == id && std::abs(f.render.depth_m[px] - p.z) < 0.01f;
            if (valid) {
              for (int ch = 0; ch < 3; ++ch) {
                rgb[ch] = std::clamp(f.render.linear_rgb[3 * px + ch], 0.0f, 1.0f);
              }
            }
          }
        }
        face.sample_rgb.push_back(rgb);
        face.sample_normals.push_back(n);
        face.sample_valid.push_back(valid ? 1 : 0);
      }
    }
  }
  return f;
}

// --- Source ----------------------------------------------------------------------------------

namespace {

bool EmitsAt(uint64_t index, double rate_hz, double fps) {
  if (rate_hz <= 0 || rate_hz >= fps) return true;
  if (index == 0) return true;
  return std::floor(static_cast<double>(index) * rate_hz / fps) >
         std::floor(static_cast<double>(index - 1) * rate_hz / fps);
}

void FillHeader(msgs::Header& h, uint64_t stamp_ns, uint64_t sequence, const std::string& frame) {
  h.stamp_ns = static_cast<int64_t>(stamp_ns);
  h.stamp_mono_ns = 0;
  h.sequence = sequence;
  h.SetFrameId(frame);
}

class SimSource final : public dataset::Source {
 public:
  SimSource(Scenario scenario, const SimOptions& options)
      : options_(options), path_(scenario.path), simulator_(std::move(scenario), options.threads) {
    const Scenario& s = simulator_.scenario();
    frames_ = options.max_frames == 0 ? s.frames : std::min(s.frames, options.max_frames);
    const int w = s.camera.width;
    const int h = s.camera.height;
    uint64_t light_count = 0;
    uint64_t face_count = 0;
    for (uint64_t i = 0; i < frames_; ++i) {
      light_count += EmitsAt(i, s.light_rate_hz, s.fps) ? 1 : 0;
      face_count += EmitsAt(i, s.face_rate_hz, s.fps) ? 1 : 0;
    }
    auto add = [&](std::string topic, std::string_view type, uint64_t hash, size_t bytes,
                   uint64_t count) {
      topics_.push_back({std::move(topic), std::string(type), hash, bytes, count});
      return topics_.size() - 1;
    };
    const std::string& cam = options.topic_prefix;
    const std::string& gt = options.ground_truth_prefix;
    info_ = add(cam + "/camera_info", msgs::CameraInfo::kTypeName, msgs::CameraInfo::kLayoutHash,
                sizeof(msgs::CameraInfo), frames_);
    image_ = add(cam + "/image", msgs::Image::kTypeName, msgs::Image::kLayoutHash,
                 msgs::Image::MessageBytesFor(w, h, msgs::Encoding::kRgb8), frames_);
    depth_ = add(cam + "/depth", msgs::Image::kTypeName, msgs::Image::kLayoutHash,
                 msgs::Image::MessageBytesFor(w, h, msgs::Encoding::kDepth16), frames_);
    pose_ = add(gt + "/pose", msgs::Pose::kTypeName, msgs::Pose::kLayoutHash, sizeof(msgs::Pose),
                frames_);
    light_ = add(gt + "/light", msgs::ShLight::kTypeName, msgs::ShLight::kLayoutHash,
                 sizeof(msgs::ShLight), light_count);
    has_face_ =
        std::any_of(s.objects.begin(), s.objects.end(), [](const ObjectSpec& o) { return o.face; });
    if (has_face_) {
      face_ = add(gt + "/face", msgs::FaceObservation::kTypeName,
                  msgs::FaceObservation::kLayoutHash, sizeof(msgs::FaceObservation), face_count);
      face_light_ = add(gt + "/face_light", msgs::ShLight::kTypeName, msgs::ShLight::kLayoutHash,
                        sizeof(msgs::ShLight), light_count);
    }
  }

  std::string_view kind() const override { return "sim"; }
  const std::string& path() const override { return path_; }
  const std::vector<dataset::TopicInfo>& topics() const override { return topics_; }
  std::optional<std::pair<uint64_t, uint64_t>> time_range() const override {
    return std::make_pair(uint64_t{0}, TimeOf(frames_ - 1));
  }
  void Rewind() override {
    next_ = 0;
    pending_.clear();
  }

  std::optional<dataset::StreamMessage> Next() override {
    if (pending_.empty()) {
      if (next_ >= frames_) return std::nullopt;
      Emit(simulator_.Render(next_));
      ++next_;
      if (options_.progress) options_.progress(next_, frames_);
    }
    dataset::StreamMessage m = std::move(pending_.front());
    pending_.pop_front();
    return m;
  }

 private:
  uint64_t TimeOf(uint64_t index) const {
    return static_cast<uint64_t>(
        std::llround(static_cast<double>(index) * 1e9 / simulator_.scenario().fps));
  }

  template <class M>
  msgs::WriteView<M> Start(size_t topic, uint64_t time, size_t bytes) {
    dataset::StreamMessage m;
    m.topic_index = topic;
    m.log_time_ns = time;
    m.message = log::MessageBuffer(bytes);
    pending_.push_back(std::move(m));
    return msgs::WriteMessage<M>(pending_.back().message.bytes());
  }

  void Emit(const SimFrame& f) {
    const Scenario& s = simulator_.scenario();
    const uint64_t t = TimeOf(f.index);
    const uint64_t seq = f.index + 1;
    const std::string& cam = s.camera_frame_id;
    const int w = f.camera.width;
    const int h = f.camera.height;
    {
      auto info = Start<msgs::CameraInfo>(info_, t, sizeof(msgs::CameraInfo));
      FillHeader(info->header, t, seq, cam);
      info->width = static_cast<uint32_t>(w);
      info->height = static_cast<uint32_t>(h);
      info->fx = f.camera.fx;
      info->fy = f.camera.fy;
      info->cx = f.camera.cx;
      info->cy = f.camera.cy;
      // A pinhole camera, written as ROS writes one: plumb_bob with five zeros.
      info->distortion_model = msgs::DistortionModel::kPlumbBob;
      info->distortion_count = 5;
      for (int i = 0; i < 5; ++i) info->distortion[i] = 0;
      info->depth_scale = 0.001;
    }
    {
      auto image = Start<msgs::Image>(image_, t, topics_[image_].max_message_bytes);
      FillHeader(image->header, t, seq, cam);
      image->Init(w, h, msgs::Encoding::kRgb8);
      std::memcpy(image.payload.data(), f.rgb.data(), f.rgb.size());
    }
    {
      auto depth = Start<msgs::Image>(depth_, t, topics_[depth_].max_message_bytes);
      FillHeader(depth->header, t, seq, cam);
      depth->Init(w, h, msgs::Encoding::kDepth16);
      std::memcpy(depth.payload.data(), f.depth_mm.data(), f.depth_mm.size() * 2);
    }
    {
      auto pose = Start<msgs::Pose>(pose_, t, sizeof(msgs::Pose));
      FillHeader(pose->header, t, seq, s.world_frame_id);
      pose->SetParentFrameId(s.world_frame_id);
      pose->SetChildFrameId(cam);
      SetTransform(pose->transform, f.camera.camera_to_world);
    }
    if (EmitsAt(f.index, s.light_rate_hz, s.fps)) {
      // /groundtruth/light: at the camera; /groundtruth/face_light: at the face origin (what a
      // face-based estimate sees). Both in the camera frame.
      auto emit = [&](size_t topic, const raytrace::LightingGroundTruth& truth) {
        auto light = Start<msgs::ShLight>(topic, t, sizeof(msgs::ShLight));
        FillHeader(light->header, t, seq, cam);
        // Times the frame's exposure: in the units of the image it goes with.
        const float e = static_cast<float>(f.exposure);
        light->bands = 3;
        for (int i = 0; i < 9; ++i) {
          for (int ch = 0; ch < 3; ++ch) light->coefficients[i][ch] = e * truth.sh[i][ch];
        }
        for (int k = 0; k < 3; ++k) light->dominant_direction[k] = truth.dominant_direction[k];
        light->intensity = e * truth.dominant_irradiance;
        light->confidence = 1;
        light->units = msgs::ShLightUnits::kLinear;
      };
      emit(light_, f.light);
      if (has_face_) emit(face_light_, f.face_light);
    }
    if (has_face_ && EmitsAt(f.index, s.face_rate_hz, s.fps)) {
      auto face = Start<msgs::FaceObservation>(face_, t, sizeof(msgs::FaceObservation));
      FillHeader(face->header, t, seq, cam);
      if (f.face.in_view) {
        face->face_detected = 1;
        face->quality = 1;
        face->landmark_count = static_cast<uint32_t>(
            std::min<size_t>(f.face.landmarks.size(), msgs::kMaxFaceLandmarks));
        for (uint32_t i = 0; i < face->landmark_count; ++i) {
          face->landmarks[i][0] = f.face.landmarks[i][0];
          face->landmarks[i][1] = f.face.landmarks[i][1];
        }
        SetTransform(face->head_pose, f.face.head_pose);
        face->sample_count = static_cast<uint32_t>(
            std::min<size_t>(f.face.sample_rgb.size(), msgs::kMaxFaceSamples));
        for (uint32_t i = 0; i < face->sample_count; ++i) {
          for (int k = 0; k < 3; ++k) {
            face->sample_rgb[i][k] = f.face.sample_rgb[i][k];
            face->sample_normals[i][k] = f.face.sample_normals[i][k];
          }
          face->SetSampleValid(i, f.face.sample_valid[i] != 0);
        }
      }
    }
  }

  static void SetTransform(msgs::RigidTransform& out, const Transform& in) {
    out.translation = {in.translation[0], in.translation[1], in.translation[2]};
    const std::array<double, 4> q = in.rotation.ToQuaternion();
    out.rotation = {q[0], q[1], q[2], q[3]};
  }

  SimOptions options_;
  std::string path_;
  Simulator simulator_;
  uint64_t frames_ = 0;
  std::vector<dataset::TopicInfo> topics_;
  size_t info_ = 0, image_ = 0, depth_ = 0, pose_ = 0, light_ = 0, face_ = 0, face_light_ = 0;
  bool has_face_ = false;
  uint64_t next_ = 0;
  std::deque<dataset::StreamMessage> pending_;
};

}  // namespace

std::unique_ptr<dataset::Source> OpenSimSource(Scenario scenario, const SimOptions& options) {
  if (options.threads < 1) throw ScenarioError("sim: threads must be >= 1");
  for (const std::string* prefix : {&options.topic_prefix, &options.ground_truth_prefix}) {
    if (prefix->size() < 2 || prefix->front() != '/' || prefix->back() == '/') {
      throw ScenarioError("sim: topic prefix '" + *prefix +
                          "' must be absolute without a trailing '/' (e.g. /camera)");
    }
  }
  return std::make_unique<SimSource>(std::move(scenario), options);
}

std::unique_ptr<dataset::Source> OpenSimSource(const std::string& path, const SimOptions& options) {
  return OpenSimSource(LoadScenario(path), options);
}

}  // namespace probeless::sim
