#include "scene_prep.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <deque>
#include <fstream>
#include <functional>
#include <memory>

#include "probeless/dataset/datasets.h"
#include "probeless/eval/metrics.h"
#include "probeless/msgs/msgs.h"
#include "probeless/raytrace/mesh.h"
#include "probeless/replay/sources.h"

namespace probeless::composite_eval {

namespace {

constexpr double kSqrtFourPi = 3.5449077018110318;  // integral of Y_00 over the sphere

log::MessageBuffer CopyBuffer(const log::MessageBuffer& from) {
  log::MessageBuffer to(from.size());
  std::memcpy(to.bytes().data(), from.bytes().data(), from.size());
  return to;
}

template <class M>
dataset::TopicInfo Topic(const std::string& name, size_t bytes) {
  return {name, std::string(M::kTypeName), M::kLayoutHash, bytes, 0};
}

// The dataset source with the evaluation's per-frame messages after each frame's own (see
// WriteSceneLog); records SceneInfo on the way.
class EvalSource : public dataset::Source {
 public:
  EvalSource(std::unique_ptr<dataset::Source> inner, const eval::Truth* truth, bool late_depth,
             SceneInfo& info)
      : inner_(std::move(inner)), truth_(truth), late_depth_(late_depth), info_(info) {
    topics_ = inner_->topics();
    for (size_t i = 0; i < topics_.size(); ++i) {
      const std::string& t = topics_[i].topic;
      if (t == "/camera/camera_info") info_topic_ = i;
      if (t == "/camera/image") image_topic_ = i;
      if (t == "/camera/depth") depth_topic_ = i;
      if (t == "/groundtruth/pose") pose_topic_ = i;
      if (t == "/camera/depth") depth_bytes_ = topics_[i].max_message_bytes;
    }
    if (late_depth_ && depth_topic_ != kNone) {
      late_depth_topic_ = topics_.size();
      topics_.push_back(Topic<msgs::Image>("/composite_eval/depth", depth_bytes_));
    }
    oracle_topic_ = topics_.size();
    topics_.push_back(Topic<msgs::ShLight>("/composite_eval/light_oracle", sizeof(msgs::ShLight)));
    baseline_topic_ = topics_.size();
    topics_.push_back(
        Topic<msgs::ShLight>("/composite_eval/light_baseline", sizeof(msgs::ShLight)));
  }

  std::string_view kind() const override { return inner_->kind(); }
  const std::string& path() const override { return inner_->path(); }
  const std::vector<dataset::TopicInfo>& topics() const override { return topics_; }
  void Rewind() override {}  // one pass only (ConvertToMcap)

  std::optional<dataset::StreamMessage> Next() override {
    while (pending_.empty() && !done_) {
      std::optional<dataset::StreamMessage> m = inner_->Next();
      if (!m) {
        FlushFrame();
        done_ = true;
        break;
      }
      if (frame_open_ && m->log_time_ns != frame_log_time_) FlushFrame();
      Record(*m);
      pending_.push_back(std::move(*m));
    }
    if (pending_.empty()) return std::nullopt;
    dataset::StreamMessage out = std::move(pending_.front());
    pending_.pop_front();
    return out;
  }

 private:
  static constexpr size_t kNone = static_cast<size_t>(-1);

  void Record(const dataset::StreamMessage& m) {
    if (!frame_open_) {
      frame_open_ = true;
      frame_log_time_ = m.log_time_ns;
      frame_ = FrameInfo{};
      frame_header_ = {};
      late_.reset();
    }
    const auto bytes = std::span<const std::byte>(m.message.bytes());
    if (m.topic_index == info_topic_) {
      const auto c = msgs::ReadMessage<msgs::CameraInfo>(bytes);
      if (info_.width == 0) {
        info_.camera_info = *c;
        info_.width = static_cast<int>(c->width);
        info_.height = static_cast<int>(c->height);
      }
    } else if (m.topic_index == image_topic_) {
      const auto image = msgs::ReadMessage<msgs::Image>(bytes);
      frame_header_ = image->header;
      frame_.stamp_ns = image->header.stamp_ns;
      std::array<double, 3> sum = {0, 0, 0};
      const uint32_t w = image->width, h = image->height;
      if (image->encoding == msgs::Encoding::kRgb8) {
        for (uint32_t y = 0; y < h; ++y) {
          const auto* row = reinterpret_cast<const uint8_t*>(image.payload.data()) +
                            static_cast<size_t>(y) * image->step;
          for (uint32_t x = 0; x < w; ++x) {
            for (int c = 0; c < 3; ++c) sum[c] += eval::SrgbToLinear(row[x * 3 + c]);
          }
        }
      }
      const double n = std::max<double>(1.0, static_cast<double>(w) * h);
      for (int c = 0; c < 3; ++c) frame_.mean_linear[c] = sum[c] / n;
    } else if (m.topic_index == depth_topic_) {
      frame_.has_depth = true;
      const auto depth = msgs::ReadMessage<msgs::Image>(bytes);
      if (info_.first_depth_stamp < 0 && depth->encoding == msgs::Encoding::kDepth16) {
        info_.first_depth_stamp = depth->header.stamp_ns;
        info_.first_depth_mm.assign(static_cast<size_t>(depth->width) * depth->height, 0);
        for (uint32_t y = 0; y < depth->height; ++y) {
          std::memcpy(info_.first_depth_mm.data() + static_cast<size_t>(y) * depth->width,
                      depth.payload.data() + static_cast<size_t>(y) * depth->step,
                      depth->width * sizeof(uint16_t));
        }
      }
      if (late_depth_topic_ != kNone) late_ = CopyBuffer(m.message);
    } else if (m.topic_index == pose_topic_) {
      const auto p = msgs::ReadMessage<msgs::Pose>(bytes);
      const auto& q = p->transform.rotation;
      const auto& t = p->transform.translation;
      frame_.camera_to_world = Rigid::FromQuaternion(q.x, q.y, q.z, q.w, {t.x, t.y, t.z});
    }
  }

  // A light message with the frame's header; `fill` sets the coefficients (WriteMessage constructs
  // the struct, so everything is written through one view).
  dataset::StreamMessage Light(size_t topic, uint64_t log_time,
                               const std::function<void(msgs::ShLight&)>& fill) {
    dataset::StreamMessage m;
    m.topic_index = topic;
    m.log_time_ns = log_time;
    m.message = log::MessageBuffer(sizeof(msgs::ShLight));
    auto light = msgs::WriteMessage<msgs::ShLight>(m.message.bytes());
    light->header = frame_header_;
    light->bands = 3;
    light->confidence = 1;
    light->units = msgs::ShLightUnits::kLinear;  // truth.json's probe and the image's mean
    fill(*light);
    return m;
  }

  void FlushFrame() {
    if (!frame_open_) return;
    frame_open_ = false;
    info_.frames.push_back(frame_);
    if (late_) {
      dataset::StreamMessage d;
      d.topic_index = late_depth_topic_;
      d.log_time_ns = frame_log_time_ + 1;
      d.message = std::move(*late_);
      late_.reset();
      pending_.push_back(std::move(d));
    }
    const eval::TruthFrame* truth = truth_ != nullptr ? truth_->Find(frame_.stamp_ns) : nullptr;
    if (truth != nullptr && truth->sh_camera) {
      pending_.push_back(Light(oracle_topic_, frame_log_time_ + 2, [&](msgs::ShLight& light) {
        for (int k = 0; k < 9; ++k) {
          for (int c = 0; c < 3; ++c) {
            light.coefficients[k][c] = static_cast<float>((*truth->sh_camera)[k][c]);
          }
        }
        if (truth->direction_camera) {
          for (int c = 0; c < 3; ++c) {
            light.dominant_direction[c] = static_cast<float>((*truth->direction_camera)[c]);
          }
        }
      }));
      ++info_.oracle_lights;
    }
    // Uniform radiance L reads L on a white Lambertian surface: coefficient 0 = L sqrt(4 pi).
    pending_.push_back(Light(baseline_topic_, frame_log_time_ + 3, [&](msgs::ShLight& light) {
      for (int c = 0; c < 3; ++c) {
        light.coefficients[0][c] = static_cast<float>(frame_.mean_linear[c] * kSqrtFourPi);
      }
      light.intensity = static_cast<float>(
          (frame_.mean_linear[0] + frame_.mean_linear[1] + frame_.mean_linear[2]) / 3);
    }));
  }

  std::unique_ptr<dataset::Source> inner_;
  const eval::Truth* truth_;
  bool late_depth_;
  SceneInfo& info_;
  std::vector<dataset::TopicInfo> topics_;
  size_t info_topic_ = kNone, image_topic_ = kNone, depth_topic_ = kNone, pose_topic_ = kNone;
  size_t late_depth_topic_ = kNone, oracle_topic_ = kNone, baseline_topic_ = kNone;
  size_t depth_bytes_ = 0;
  std::deque<dataset::StreamMessage> pending_;
  bool done_ = false;
  bool frame_open_ = false;
  uint64_t frame_log_time_ = 0;
  FrameInfo frame_;
  msgs::Header frame_header_;
  std::optional<log::MessageBuffer> late_;
};

void WriteMeshObj(const raytrace::Mesh& mesh, const std::string& path, const std::string& what) {
  std::ofstream out(path);
  if (!out) throw eval::EvalError("cannot write " + path);
  out << "# " << what << " (composite_eval), fusion's world frame\n";
  char line[160];
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    const raytrace::Vec3& p = mesh.positions[i];
    if (!mesh.colors.empty()) {
      const raytrace::Vec3& c = mesh.colors[i];
      std::snprintf(line, sizeof line, "v %.6f %.6f %.6f %.4f %.4f %.4f\n", p.x, p.y, p.z, c.x, c.y,
                    c.z);
    } else {
      std::snprintf(line, sizeof line, "v %.6f %.6f %.6f\n", p.x, p.y, p.z);
    }
    out << line;
  }
  for (const raytrace::Vec3& n : mesh.normals) {
    std::snprintf(line, sizeof line, "vn %.6f %.6f %.6f\n", n.x, n.y, n.z);
    out << line;
  }
  const bool normals = mesh.normals.size() == mesh.positions.size();
  for (const auto& t : mesh.triangles) {
    if (normals) {
      out << "f " << t[0] + 1 << "//" << t[0] + 1 << ' ' << t[1] + 1 << "//" << t[1] + 1 << ' '
          << t[2] + 1 << "//" << t[2] + 1 << '\n';
    } else {
      out << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
    }
  }
  if (!out) throw eval::EvalError("cannot write " + path);
}

}  // namespace

std::array<double, 3> Rigid::Apply(const std::array<double, 3>& p) const {
  return {r[0] * p[0] + r[1] * p[1] + r[2] * p[2] + t[0],
          r[3] * p[0] + r[4] * p[1] + r[5] * p[2] + t[1],
          r[6] * p[0] + r[7] * p[1] + r[8] * p[2] + t[2]};
}

Rigid Rigid::Inverse() const {
  Rigid inv;
  inv.r = {r[0], r[3], r[6], r[1], r[4], r[7], r[2], r[5], r[8]};
  const std::array<double, 3> minus_t = inv.Apply(t);
  inv.t = {-minus_t[0], -minus_t[1], -minus_t[2]};
  return inv;
}

Rigid Rigid::Compose(const Rigid& inner) const {
  Rigid out;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      out.r[i * 3 + j] =
          r[i * 3] * inner.r[j] + r[i * 3 + 1] * inner.r[3 + j] + r[i * 3 + 2] * inner.r[6 + j];
    }
  }
  out.t = Apply(inner.t);
  return out;
}

Rigid Rigid::FromQuaternion(double x, double y, double z, double w,
                            const std::array<double, 3>& t) {
  const double n = std::sqrt(x * x + y * y + z * z + w * w);
  if (n > 0) {
    x /= n;
    y /= n;
    z /= n;
    w /= n;
  }
  Rigid out;
  out.r = {1 - 2 * (y * y + z * z), 2 * (x * y - z * w),     2 * (x * z + y * w),
           2 * (x * y + z * w),     1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
           2 * (x * z - y * w),     2 * (y * z + x * w),     1 - 2 * (x * x + y * y)};
  out.t = t;
  return out;
}

SceneInfo WriteSceneLog(const std::string& scene_dir, const eval::Truth* truth, bool late_depth,
                        const std::string& mcap_path) {
  SceneInfo info;
  EvalSource source(dataset::OpenDataset("tum:" + scene_dir), truth, late_depth, info);
  log::WriterOptions options;
  options.compression = log::Compression::kNone;  // a temporary file read once: speed over size
  replay::ConvertToMcap(source, mcap_path, options);
  return info;
}

void SetCamera(SceneInfo& info, const rectify::Rectifier* rectifier) {
  const msgs::CameraInfo& c = rectifier ? rectifier->rectified_info() : info.camera_info;
  info.fx = c.fx;
  info.fy = c.fy;
  info.cx = c.cx;
  info.cy = c.cy;
  std::vector<uint16_t> depth = info.first_depth_mm;
  if (rectifier != nullptr && !depth.empty()) {
    msgs::Image in;
    in.Init(static_cast<uint32_t>(info.width), static_cast<uint32_t>(info.height),
            msgs::Encoding::kDepth16);
    msgs::Image out;
    rectifier->Rectify(in, std::as_bytes(std::span(info.first_depth_mm)), out,
                       std::as_writable_bytes(std::span(depth)), "first depth image");
  }
  info.first_depth_m.resize(depth.size());
  for (size_t i = 0; i < depth.size(); ++i) info.first_depth_m[i] = depth[i] * 0.001f;
}

Rigid FusionWorldFromTruthWorld(const SceneInfo& info, const std::string& scene) {
  for (const FrameInfo& f : info.frames) {
    if (f.stamp_ns != info.first_depth_stamp) continue;
    if (!f.camera_to_world) {
      throw eval::EvalError(scene +
                            ": the first frame with depth has no ground-truth pose "
                            "(groundtruth.txt): fusion's world cannot be placed");
    }
    return f.camera_to_world->Inverse();
  }
  throw eval::EvalError(scene + ": no frame with a depth image (depth.txt)");
}

void WriteObjectObj(const eval::InsertedObject& object, const Rigid& fusion_from_truth,
                    const std::string& path) {
  raytrace::Mesh mesh = object.shape == eval::Shape::kSphere
                            ? raytrace::MakeSphere(static_cast<float>(object.radius), 64)
                            : raytrace::MakeBox({static_cast<float>(object.size[0]),
                                                 static_cast<float>(object.size[1]),
                                                 static_cast<float>(object.size[2])});
  const Rigid object_to_truth =
      Rigid::FromQuaternion(object.rotation[0], object.rotation[1], object.rotation[2],
                            object.rotation[3], object.position);
  const Rigid to_fusion = fusion_from_truth.Compose(object_to_truth);
  for (raytrace::Vec3& p : mesh.positions) {
    const auto q = to_fusion.Apply({p.x, p.y, p.z});
    p = {static_cast<float>(q[0]), static_cast<float>(q[1]), static_cast<float>(q[2])};
  }
  Rigid rotation = to_fusion;
  rotation.t = {0, 0, 0};
  for (raytrace::Vec3& n : mesh.normals) {
    const auto q = rotation.Apply({n.x, n.y, n.z});
    n = {static_cast<float>(q[0]), static_cast<float>(q[1]), static_cast<float>(q[2])};
  }
  mesh.colors.assign(mesh.positions.size(),
                     {static_cast<float>(object.albedo[0]), static_cast<float>(object.albedo[1]),
                      static_cast<float>(object.albedo[2])});
  WriteMeshObj(mesh, path, object.shape == eval::Shape::kSphere ? "sphere" : "box");
}

size_t WriteDepthProxyObj(const SceneInfo& info, int stride, const std::string& path) {
  const int w = info.width, h = info.height;
  if (info.first_depth_m.size() != static_cast<size_t>(w) * h) {
    throw eval::EvalError(path + ": the first depth image does not match the camera size");
  }
  const int nx = (w - 1) / stride + 1, ny = (h - 1) / stride + 1;
  std::vector<int32_t> index(static_cast<size_t>(nx) * ny, -1);
  raytrace::Mesh mesh;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const int u = i * stride, v = j * stride;
      const float z = info.first_depth_m[static_cast<size_t>(v) * w + u];
      if (!(z > 0)) continue;
      index[static_cast<size_t>(j) * nx + i] = static_cast<int32_t>(mesh.positions.size());
      mesh.positions.push_back({static_cast<float>((u - info.cx) / info.fx * z),
                                static_cast<float>((v - info.cy) / info.fy * z), z});
    }
  }
  auto depth_at = [&](int32_t k) { return mesh.positions[k].z; };
  auto add = [&](int32_t a, int32_t b, int32_t c) {
    if (a < 0 || b < 0 || c < 0) return;
    const float lo = std::min({depth_at(a), depth_at(b), depth_at(c)});
    const float hi = std::max({depth_at(a), depth_at(b), depth_at(c)});
    if (hi > lo * 1.05f) return;  // a depth jump: not one surface
    // (u, v), (u, v + 1), (u + 1, v) is counter-clockwise seen from the camera.
    mesh.triangles.push_back(
        {static_cast<uint32_t>(a), static_cast<uint32_t>(b), static_cast<uint32_t>(c)});
  };
  for (int j = 0; j + 1 < ny; ++j) {
    for (int i = 0; i + 1 < nx; ++i) {
      const int32_t a = index[static_cast<size_t>(j) * nx + i];
      const int32_t b = index[static_cast<size_t>(j + 1) * nx + i];
      const int32_t c = index[static_cast<size_t>(j) * nx + i + 1];
      const int32_t d = index[static_cast<size_t>(j + 1) * nx + i + 1];
      add(a, b, c);
      add(c, b, d);
    }
  }
  if (mesh.triangles.empty()) {
    throw eval::EvalError(path + ": the first depth image gives no surface for the scene proxy");
  }
  mesh.ComputeNormals();
  WriteMeshObj(mesh, path, "first depth image as the real-scene proxy");
  return mesh.positions.size();
}

VolumeParams ChooseVolume(const SceneInfo& info, const std::vector<eval::InsertedObject>& objects,
                          const Rigid& fusion_from_truth) {
  std::array<double, 3> lo = {1e9, 1e9, 1e9}, hi = {-1e9, -1e9, -1e9};
  auto grow = [&](const std::array<double, 3>& p, double r) {
    for (int c = 0; c < 3; ++c) {
      lo[c] = std::min(lo[c], p[c] - r);
      hi[c] = std::max(hi[c], p[c] + r);
    }
  };
  std::vector<double> depths;
  const int w = info.width;
  for (size_t k = 0; k < info.first_depth_m.size(); k += 7) {
    const float z = info.first_depth_m[k];
    if (!(z > 0)) continue;
    depths.push_back(z);
    const int u = static_cast<int>(k % w), v = static_cast<int>(k / w);
    grow({(u - info.cx) / info.fx * z, (v - info.cy) / info.fy * z, z}, 0);
  }
  for (const eval::InsertedObject& o : objects) {
    grow(fusion_from_truth.Apply(o.position), o.BoundingRadius());
  }
  VolumeParams v;
  if (depths.empty()) return v;
  const double p99 = *eval::Percentile(depths, 0.99);
  v.depth_max = std::clamp(p99 + 0.5, 4.0, 10.0);
  double edge = 0;
  for (int c = 0; c < 3; ++c) edge = std::max(edge, hi[c] - lo[c]);
  v.size = std::clamp(edge + 0.4, 1.0, 8.0);
  for (int c = 0; c < 3; ++c) v.origin[c] = 0.5 * (lo[c] + hi[c]) - 0.5 * v.size;
  v.truncation = std::max(0.03, 4.0 * v.size / 256.0);
  return v;
}

bool VisibleInSomeFrame(const SceneInfo& info, const eval::InsertedObject& object) {
  const double r = object.BoundingRadius();
  for (const FrameInfo& f : info.frames) {
    if (!f.camera_to_world) continue;
    const auto p = f.camera_to_world->Inverse().Apply(object.position);
    if (p[2] <= 0.01) continue;
    const double u = info.fx * p[0] / p[2] + info.cx, v = info.fy * p[1] / p[2] + info.cy;
    const double ru = info.fx * r / p[2], rv = info.fy * r / p[2];
    if (u + ru >= -0.5 && u - ru <= info.width - 0.5 && v + rv >= -0.5 &&
        v - rv <= info.height - 0.5) {
      return true;
    }
  }
  return false;
}

}  // namespace probeless::composite_eval
