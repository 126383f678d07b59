#include "probeless/render/msgs_io.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "probeless/sh/sh.h"

namespace probeless::render {

ShLightRgb LightFromMsg(const msgs::ShLight& light) {
  try {
    light.Validate();
  } catch (const std::exception& e) {
    throw RenderError(e.what());
  }
  ShLightRgb out;
  out.bands = static_cast<int>(light.bands);
  for (uint32_t k = 0; k < light.CoefficientCount(); ++k) {
    for (int c = 0; c < 3; ++c) out.coefficients[k][c] = light.coefficients[k][c];
  }
  return out;
}

light::DominantLight DominantLightFromMsg(const msgs::ShLight& light) {
  light::DominantLight d;
  const float* md = light.dominant_direction;
  if (light.intensity > 0 && md[0] * md[0] + md[1] * md[1] + md[2] * md[2] > 0.5f) {
    d.direction = {md[0], md[1], md[2]};
    d.intensity = light.intensity;
    return d;
  }
  if (light.bands < 2) return d;
  std::vector<double> grey(light.bands * light.bands);
  for (size_t k = 0; k < grey.size(); ++k) {
    grey[k] =
        (light.coefficients[k][0] + light.coefficients[k][1] + light.coefficients[k][2]) / 3.0;
  }
  const sh::Vec3 dir = sh::OptimalLinearDirection(grey.data());
  if (dir[0] == 0 && dir[1] == 0 && dir[2] == 0) return d;
  d.direction = {static_cast<float>(dir[0]), static_cast<float>(dir[1]),
                 static_cast<float>(dir[2])};
  d.intensity = static_cast<float>(std::max(0.0, sh::DirectionalPower(grey, dir)));
  return d;
}

bool AcceptLightUnits(msgs::ShLightUnits units, std::string* warning) {
  warning->clear();
  switch (units) {
    case msgs::ShLightUnits::kLinear:
      return true;
    case msgs::ShLightUnits::kUnknown:
      *warning =
          "light has unknown units (recorded before ShLight had a units field): shaded as "
          "linear radiance";
      return true;
    case msgs::ShLightUnits::kLinearUnscaled:
      *warning =
          "light is linear_unscaled (its scale is arbitrary): shaded as linear radiance, "
          "the objects' brightness will not match the image";
      return true;
    case msgs::ShLightUnits::kFaceModel:
      *warning =
          "light is in face_model units (a face model's compressed I^g, not radiance): not "
          "rendered; publish linear light (face_light linear_output:=true)";
      return false;
  }
  *warning = "light has units " + std::to_string(static_cast<uint32_t>(units)) +
             ", not a msgs::ShLightUnits value: not rendered";
  return false;
}

raytrace::Transform TransformFromMsg(const msgs::RigidTransform& t) {
  const msgs::Quaternion& q = t.rotation;
  const double n = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  if (!(n > 0)) throw RenderError("transform: zero (unset) rotation quaternion");
  raytrace::Transform out;
  out.rotation = raytrace::Mat3::FromQuaternion(q.w / n, q.x / n, q.y / n, q.z / n);
  out.translation = {t.translation.x, t.translation.y, t.translation.z};
  return out;
}

Intrinsics IntrinsicsFromMsg(const msgs::CameraInfo& info) {
  Intrinsics k;
  k.width = static_cast<int>(info.width);
  k.height = static_cast<int>(info.height);
  k.fx = info.fx;
  k.fy = info.fy;
  k.cx = info.cx;
  k.cy = info.cy;
  k.Validate();
  return k;
}

Intrinsics DefaultIntrinsics(int width, int height) {
  Intrinsics k;
  k.width = width;
  k.height = height;
  k.fx = k.fy = 525.0 * width / 640.0;
  k.cx = (width - 1) / 2.0;
  k.cy = (height - 1) / 2.0;
  return k;
}

void ImageToRgb(const msgs::Image& image, std::span<const std::byte> payload,
                std::vector<uint8_t>& rgb) {
  try {
    image.Validate(payload.size());
  } catch (const std::exception& e) {
    throw RenderError(e.what());
  }
  const size_t w = image.width, h = image.height;
  rgb.resize(w * h * 3);
  const auto* bytes = reinterpret_cast<const uint8_t*>(payload.data());
  for (size_t y = 0; y < h; ++y) {
    const uint8_t* row = bytes + y * image.step;
    uint8_t* out = rgb.data() + y * w * 3;
    switch (image.encoding) {
      case msgs::Encoding::kRgb8:
        std::memcpy(out, row, w * 3);
        break;
      case msgs::Encoding::kBgr8:
        for (size_t x = 0; x < w; ++x) {
          out[x * 3] = row[x * 3 + 2], out[x * 3 + 1] = row[x * 3 + 1], out[x * 3 + 2] = row[x * 3];
        }
        break;
      case msgs::Encoding::kMono8:
        for (size_t x = 0; x < w; ++x) out[x * 3] = out[x * 3 + 1] = out[x * 3 + 2] = row[x];
        break;
      default:
        throw RenderError("camera image " + image.Describe() +
                          ": unsupported encoding (expected rgb8, bgr8 or mono8)");
    }
  }
}

void GeometryDepth(const msgs::GeometryBuffer& g, std::span<const std::byte> payload,
                   std::vector<float>& depth) {
  try {
    const std::span<const float> plane = msgs::DepthPlane(g, payload);
    depth.assign(plane.begin(), plane.end());
  } catch (const msgs::MessageError& e) {
    throw RenderError(e.what());
  }
}

void GeometryPlanes(const msgs::GeometryBuffer& g, std::span<const std::byte> payload,
                    std::vector<float>& normals, std::vector<uint8_t>& colour) {
  try {
    const std::span<const float> n = msgs::NormalsPlane(g, payload);
    normals.assign(n.begin(), n.end());
    const std::span<const uint8_t> c = msgs::ColourPlane(g, payload);
    colour.assign(c.begin(), c.end());
  } catch (const msgs::MessageError& e) {
    throw RenderError(e.what());
  }
}

void TransferValues(const msgs::TransferBuffer& t, std::span<const std::byte> payload,
                    std::vector<float>& values) {
  try {
    const std::span<const float> all = msgs::TransferCoefficients(t, payload);
    values.assign(all.begin(), all.end());
  } catch (const msgs::MessageError& e) {
    throw RenderError(e.what());
  }
}

}  // namespace probeless::render
