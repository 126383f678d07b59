#include "probeless/light/messages.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace probeless::light {

Intrinsics IntrinsicsFrom(const msgs::CameraInfo& info, int width, int height) {
  if (!std::isfinite(info.fx) || !std::isfinite(info.fy) || !std::isfinite(info.cx) ||
      !std::isfinite(info.cy)) {
    throw LightError("light::IntrinsicsFrom: camera info has non-finite intrinsics");
  }
  if (!(info.fx > 0) || !(info.fy > 0)) {
    throw LightError("light::IntrinsicsFrom: camera info fx and fy must be > 0");
  }
  if (static_cast<int>(info.width) != width || static_cast<int>(info.height) != height) {
    throw LightError("light::IntrinsicsFrom: camera info is " + std::to_string(info.width) + "x" +
                     std::to_string(info.height) + ", buffer is " + std::to_string(width) + "x" +
                     std::to_string(height));
  }
  return {info.fx, info.fy, info.cx, info.cy};
}

GeometryView ViewOfGeometryBuffer(const msgs::GeometryBuffer& g, std::span<const std::byte> payload,
                                  const msgs::CameraInfo& info) {
  GeometryView view;
  view.width = static_cast<int>(g.width);
  view.height = static_cast<int>(g.height);
  view.intrinsics = IntrinsicsFrom(info, view.width, view.height);
  view.depth = msgs::DepthPlane(g, payload);
  view.normals = msgs::NormalsPlane(g, payload);
  view.colour = msgs::ColourPlane(g, payload);
  ValidateGeometryView(view, "ViewOfGeometryBuffer");
  bool any_depth = false;
  for (size_t p = 0; p < view.depth.size(); ++p) {
    if (!(view.depth[p] > 0)) continue;
    any_depth = true;
    if (view.normals[3 * p] != 0 || view.normals[3 * p + 1] != 0 || view.normals[3 * p + 2] != 0) {
      return view;
    }
  }
  if (any_depth) throw LightError("light::ViewOfGeometryBuffer: missing normals (all zero)");
  return view;
}

AuxiliaryBuffers AuxiliaryFromMessage(const msgs::AuxiliaryViews& message,
                                      std::span<const std::byte> payload) {
  message.Validate(payload.size());
  AuxiliaryBuffers out;
  for (uint32_t i = 0; i < message.view_count; ++i) {
    const msgs::AuxiliaryView& m = message.views[i];
    OrthographicView v;
    switch (m.role) {
      case msgs::AuxiliaryViewRole::kLeft:
        v.role = AuxiliaryRole::kLeft;
        break;
      case msgs::AuxiliaryViewRole::kRight:
        v.role = AuxiliaryRole::kRight;
        break;
      case msgs::AuxiliaryViewRole::kTop:
        v.role = AuxiliaryRole::kTop;
        break;
      case msgs::AuxiliaryViewRole::kLight:
        v.role = AuxiliaryRole::kLight;
        break;
      default:
        v.role = AuxiliaryRole::kOther;
        break;
    }
    v.width = static_cast<int>(m.width);
    v.height = static_cast<int>(m.height);
    v.pixel_size_m = m.pixel_size_m;
    for (int k = 0; k < 9; ++k) v.rotation[k] = m.rotation[k];
    for (int k = 0; k < 3; ++k) v.translation[k] = m.translation[k];
    v.depth = msgs::AuxiliaryDepth(message, payload, i);
    out.views.push_back(v);
  }
  return out;
}

void DepthFromImage(const msgs::Image& depth, std::span<const std::byte> payload,
                    const msgs::CameraInfo& info, std::vector<float>* depth_m) {
  const int w = static_cast<int>(depth.width), h = static_cast<int>(depth.height);
  IntrinsicsFrom(info, w, h);  // the size check (and finite intrinsics)
  depth_m->resize(static_cast<size_t>(w) * h);
  if (depth.encoding == msgs::Encoding::kDepth16) {
    const double scale = info.depth_scale > 0 ? info.depth_scale : 0.001;
    for (int y = 0; y < h; ++y) {
      const auto row = msgs::ImageRow<uint16_t>(depth, payload, y);
      for (int x = 0; x < w; ++x) (*depth_m)[y * w + x] = static_cast<float>(row[x] * scale);
    }
  } else if (depth.encoding == msgs::Encoding::kFloat32) {
    for (int y = 0; y < h; ++y) {
      const auto row = msgs::ImageRow<float>(depth, payload, y);
      for (int x = 0; x < w; ++x) {
        (*depth_m)[y * w + x] = std::isfinite(row[x]) && row[x] > 0 ? row[x] : 0.0f;
      }
    }
  } else {
    throw LightError("light::DepthFromImage: depth encoding " +
                     std::string(msgs::EncodingName(depth.encoding)) +
                     " is not depth16 or float32");
  }
}

void GeometryFromDepthImage(const msgs::Image& depth, std::span<const std::byte> payload,
                            const msgs::CameraInfo& info, std::vector<float>* depth_m,
                            std::vector<float>* normals, const DepthGeometryOptions& options,
                            std::vector<float>* reliability) {
  const int w = static_cast<int>(depth.width), h = static_cast<int>(depth.height);
  const Intrinsics k = IntrinsicsFrom(info, w, h);
  DepthFromImage(depth, payload, info, depth_m);
  // Raw sensor depth is quantised: DepthGeometry smooths it when its measured noise calls for it.
  DepthGeometry(*depth_m, w, h, k, options, normals, reliability);
}

void GreyFromImage(const msgs::Image& image, std::span<const std::byte> payload, int width,
                   int height, std::vector<float>* grey, std::vector<uint8_t>* rgb) {
  if (static_cast<int>(image.width) != width || static_cast<int>(image.height) != height) {
    throw LightError("light::GreyFromImage: image is " + std::to_string(image.width) + "x" +
                     std::to_string(image.height) + ", geometry is " + std::to_string(width) + "x" +
                     std::to_string(height));
  }
  grey->resize(static_cast<size_t>(width) * height);
  const bool colour =
      image.encoding == msgs::Encoding::kRgb8 || image.encoding == msgs::Encoding::kBgr8;
  if (rgb != nullptr) rgb->resize(colour ? 3 * grey->size() : 0);
  for (int y = 0; y < height; ++y) {
    const auto row = msgs::ImageRow<uint8_t>(image, payload, y);
    float* dst = grey->data() + static_cast<size_t>(y) * width;
    switch (image.encoding) {
      case msgs::Encoding::kRgb8:
      case msgs::Encoding::kBgr8:
        for (int x = 0; x < width; ++x) {
          dst[x] = (SrgbToLinear(row[3 * x]) + SrgbToLinear(row[3 * x + 1]) +
                    SrgbToLinear(row[3 * x + 2])) *
                   (1.0f / 3);
        }
        if (rgb != nullptr) {
          uint8_t* out = rgb->data() + 3 * static_cast<size_t>(y) * width;
          const bool bgr = image.encoding == msgs::Encoding::kBgr8;
          for (int x = 0; x < width; ++x) {
            out[3 * x] = row[3 * x + (bgr ? 2 : 0)];
            out[3 * x + 1] = row[3 * x + 1];
            out[3 * x + 2] = row[3 * x + (bgr ? 0 : 2)];
          }
        }
        break;
      case msgs::Encoding::kMono8:
        for (int x = 0; x < width; ++x) dst[x] = SrgbToLinear(row[x]);
        break;
      default:
        throw LightError("light::GreyFromImage: encoding " +
                         std::string(msgs::EncodingName(image.encoding)) +
                         " is not rgb8, bgr8 or mono8");
    }
  }
}

SceneFrame SceneFrameBuilder::FromGeometryBuffer(const msgs::GeometryBuffer& g,
                                                 std::span<const std::byte> payload,
                                                 const msgs::CameraInfo& info) {
  const GeometryView view = ViewOfGeometryBuffer(g, payload, info);
  SceneFrame frame;
  frame.stamp_ns = g.header.stamp_ns;
  frame.width = view.width;
  frame.height = view.height;
  frame.intrinsics = view.intrinsics;
  frame.gbuffer_depth = view.depth;
  frame.gbuffer_normals = view.normals;
  frame.gbuffer_colour = view.colour;
  return frame;
}

SceneFrame SceneFrameBuilder::FromDepthImage(const msgs::Image& depth,
                                             std::span<const std::byte> payload,
                                             const msgs::CameraInfo& info) {
  DepthFromImage(depth, payload, info, &depth_);
  SceneFrame frame;
  frame.stamp_ns = depth.header.stamp_ns;
  frame.width = static_cast<int>(depth.width);
  frame.height = static_cast<int>(depth.height);
  frame.intrinsics = IntrinsicsFrom(info, frame.width, frame.height);
  frame.depth_image = depth_;
  return frame;
}

void SceneFrameBuilder::AddImage(const msgs::Image& image, std::span<const std::byte> payload,
                                 SceneFrame* frame) {
  GreyFromImage(image, payload, frame->width, frame->height, &grey_, &rgb_);
  frame->grey = grey_;
  frame->colour = rgb_;
}

void SceneFrameBuilder::AddShadowDepth(const msgs::Image& depth, std::span<const std::byte> payload,
                                       const msgs::CameraInfo& info, SceneFrame* frame) {
  if (static_cast<int>(depth.width) != frame->width ||
      static_cast<int>(depth.height) != frame->height) {
    throw LightError("light::SceneFrameBuilder::AddShadowDepth: depth image is " +
                     std::to_string(depth.width) + "x" + std::to_string(depth.height) +
                     ", frame is " + std::to_string(frame->width) + "x" +
                     std::to_string(frame->height));
  }
  DepthFromImage(depth, payload, info, &shadow_depth_);
  frame->depth_image = shadow_depth_;
}

namespace {

// The row-major rotation matrix of the normalised quaternion q; `what` (the public function)
// names the caller in the error for a quaternion of norm 0 or not finite.
std::array<double, 9> RotationOfQuaternion(const msgs::Quaternion& q, const char* what) {
  const double n = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  if (!(n > 0) || !std::isfinite(n)) {
    throw LightError(std::string(what) + ": the camera's rotation quaternion has norm " +
                     std::to_string(n) + ", expected a finite non-zero norm");
  }
  const double w = q.w / n, x = q.x / n, y = q.y / n, z = q.z / n;
  return {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
          2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
          2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
}

}  // namespace

std::array<double, 9> CameraToWorldRotation(const msgs::RigidTransform& camera_to_world) {
  return RotationOfQuaternion(camera_to_world.rotation, "light::CameraToWorldRotation");
}

std::array<float, 3> WorldPointInCamera(const msgs::RigidTransform& camera_to_world,
                                        const std::array<double, 3>& world) {
  const std::array<double, 9> r =
      RotationOfQuaternion(camera_to_world.rotation, "light::WorldPointInCamera");
  const msgs::Vector3& t = camera_to_world.translation;
  const double d[3] = {world[0] - t.x, world[1] - t.y, world[2] - t.z};
  std::array<float, 3> out{};
  for (int c = 0; c < 3; ++c) {
    out[c] = static_cast<float>(r[0 * 3 + c] * d[0] + r[1 * 3 + c] * d[1] + r[2 * 3 + c] * d[2]);
  }
  return out;
}

void FillShLight(const LightEstimate& e, msgs::ShLight* out, float scale) {
  out->bands = static_cast<uint32_t>(std::min(e.bands, static_cast<int>(msgs::kMaxShBands)));
  for (uint32_t n = 0; n < msgs::kMaxShCoefficients; ++n) {
    const float v = n < out->CoefficientCount() && n < e.coefficients.size()
                        ? static_cast<float>(e.coefficients[n]) * scale
                        : 0.0f;
    for (int c = 0; c < 3; ++c) out->coefficients[n][c] = v;
  }
  for (int k = 0; k < 3; ++k) out->dominant_direction[k] = e.dominant_direction[k];
  out->intensity = e.intensity * scale;
  out->confidence = std::clamp(e.confidence, 0.0f, 1.0f);
  out->units = msgs::ShLightUnits::kLinear;
}

void FillIndirectImage(const TransferResult& result, msgs::Image* out,
                       std::span<std::byte> payload) {
  const size_t pixels = static_cast<size_t>(result.width) * result.height;
  if (result.indirect.size() != 3 * pixels || pixels == 0) {
    throw LightError("light::FillIndirectImage: the transfer result has no indirect buffer (" +
                     std::to_string(result.indirect.size()) + " values for " +
                     std::to_string(result.width) + "x" + std::to_string(result.height) +
                     " pixels; Compute needs a DominantLight)");
  }
  const size_t bytes =
      msgs::Image::PackedPayloadBytes(result.width, result.height, msgs::Encoding::kRgb32f);
  if (payload.size() < bytes) {
    throw LightError("light::FillIndirectImage: payload of " + std::to_string(payload.size()) +
                     " bytes, need " + std::to_string(bytes));
  }
  out->Init(result.width, result.height, msgs::Encoding::kRgb32f);
  const std::span<float> dst = msgs::ImageChannels<float>(*out, payload);
  std::copy(result.indirect.begin(), result.indirect.end(), dst.begin());
}

}  // namespace probeless::light
