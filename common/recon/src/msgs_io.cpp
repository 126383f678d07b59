#include "probeless/recon/msgs_io.h"

#include <cmath>
#include <cstring>
#include <string>

#include "probeless/recon/preprocess.h"

namespace probeless::recon {

Intrinsics IntrinsicsFromCameraInfo(const msgs::CameraInfo& info) {
  if (!std::isfinite(info.fx) || !std::isfinite(info.fy) || !std::isfinite(info.cx) ||
      !std::isfinite(info.cy)) {
    throw ReconError("camera_info: intrinsics must be finite (fx, fy, cx, cy)");
  }
  if (info.distortion_model != msgs::DistortionModel::kNone) {
    for (uint32_t i = 0; i < info.distortion_count && i < msgs::kMaxDistortionCoefficients; ++i) {
      if (info.distortion[i] != 0) {
        throw ReconError("camera_info: lens distortion (" +
                         std::string(msgs::DistortionModelName(info.distortion_model)) +
                         ") is not supported: run the rectify node in front and feed its "
                         "depth_rect, image_rect and camera_info_rect (docs/rectify.md)");
      }
    }
  }
  Intrinsics k;
  k.width = static_cast<int>(info.width);
  k.height = static_cast<int>(info.height);
  k.fx = static_cast<float>(info.fx);
  k.fy = static_cast<float>(info.fy);
  k.cx = static_cast<float>(info.cx);
  k.cy = static_cast<float>(info.cy);
  k.Validate("camera_info");
  return k;
}

void DepthFromImage(const msgs::Image& image, std::span<const std::byte> payload,
                    double metres_per_unit, float min_m, float max_m, DepthImage& out) {
  if (image.encoding != msgs::Encoding::kDepth16 && image.encoding != msgs::Encoding::kFloat32) {
    throw ReconError("depth: expected encoding depth16 or float32, got " +
                     std::string(msgs::EncodingName(image.encoding)));
  }
  if (image.width == 0 || image.height == 0) {
    throw ReconError("depth: empty image (" + std::to_string(image.width) + "x" +
                     std::to_string(image.height) + ")");
  }
  try {
    image.Validate(payload.size());
  } catch (const std::exception& e) {
    throw ReconError(std::string("depth: ") + e.what());
  }
  if (image.encoding == msgs::Encoding::kDepth16) {
    const double scale = metres_per_unit > 0 ? metres_per_unit : 0.001;
    DepthFromUnits(reinterpret_cast<const uint16_t*>(payload.data()), static_cast<int>(image.width),
                   static_cast<int>(image.height), image.step / 2, scale, min_m, max_m, out);
    return;
  }
  out.Resize(static_cast<int>(image.width), static_cast<int>(image.height));
  for (uint32_t y = 0; y < image.height; ++y) {
    const float* row = reinterpret_cast<const float*>(payload.data() + y * image.step);
    for (uint32_t x = 0; x < image.width; ++x) {
      const float d = row[x];
      out.At(x, y) = (std::isfinite(d) && d >= min_m && d <= max_m) ? d : 0.0f;
    }
  }
}

void GreyFromImage(const msgs::Image& image, std::span<const std::byte> payload, GreyImage& out) {
  if (image.encoding != msgs::Encoding::kRgb8 && image.encoding != msgs::Encoding::kBgr8 &&
      image.encoding != msgs::Encoding::kMono8) {
    throw ReconError("image: expected encoding rgb8, bgr8 or mono8, got " +
                     std::string(msgs::EncodingName(image.encoding)));
  }
  if (image.width == 0 || image.height == 0) throw ReconError("image: empty image");
  try {
    image.Validate(payload.size());
  } catch (const std::exception& e) {
    throw ReconError(std::string("image: ") + e.what());
  }
  out.Resize(static_cast<int>(image.width), static_cast<int>(image.height));
  const auto* data = reinterpret_cast<const uint8_t*>(payload.data());
  for (uint32_t y = 0; y < image.height; ++y) {
    const uint8_t* row = data + static_cast<size_t>(y) * image.step;
    for (uint32_t x = 0; x < image.width; ++x) {
      uint8_t g;
      if (image.encoding == msgs::Encoding::kMono8) {
        g = row[x];
      } else {
        const int r = row[3 * x + (image.encoding == msgs::Encoding::kRgb8 ? 0 : 2)];
        const int b = row[3 * x + (image.encoding == msgs::Encoding::kRgb8 ? 2 : 0)];
        g = static_cast<uint8_t>((77 * r + 150 * row[3 * x + 1] + 29 * b) >> 8);
      }
      out.At(x, y) = g;
    }
  }
}

DepthFrame DepthFrameFromMessages(const msgs::Image& depth, std::span<const std::byte> payload,
                                  const msgs::CameraInfo& info, float min_m, float max_m) {
  DepthFrame d;
  d.header = depth.header;
  d.intrinsics = IntrinsicsFromCameraInfo(info);
  DepthFromImage(depth, payload, info.depth_scale, min_m, max_m, d.depth);
  return d;
}

ColourFrame ColourFrameFromMessage(const msgs::Image& image, std::span<const std::byte> payload) {
  ColourFrame c;
  c.image = image;
  GreyFromImage(image, payload, c.grey);
  c.payload.assign(payload.begin(), payload.begin() + image.PayloadBytes());
  return c;
}

std::optional<Vec3f> DominantDirection(const msgs::ShLight& light) {
  const float* dir = light.dominant_direction;
  const float len2 = dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2];
  if (!(len2 > 1e-6f) || !std::isfinite(len2)) return std::nullopt;
  return Vec3f{dir[0], dir[1], dir[2]};
}

void FillTrackingStatus(const FrameResult& r, const TrackingCounts& counts,
                        msgs::TrackingStatus* out) {
  out->state = r.state == TrackingState::kLost        ? msgs::TrackingStatusState::kLost
               : r.state == TrackingState::kUncertain ? msgs::TrackingStatusState::kUncertain
                                                      : msgs::TrackingStatusState::kTracked;
  out->score = r.quality.score;
  out->reasons = r.quality.reasons;
  out->integrated = r.integrated ? 1 : 0;
  out->relocalised = r.relocalised ? 1 : 0;
  out->rms_m = r.icp.rms_m;
  out->inlier_fraction = r.icp.inlier_fraction;
  out->residual_ratio = r.quality.residual_ratio;
  out->inlier_ratio = r.quality.inlier_ratio;
  out->motion_translation_m = r.quality.motion_translation_m;
  out->motion_rotation_deg = r.quality.motion_rotation_deg;
  out->observability = r.quality.observability;
  out->frames = counts.frames;
  out->tracked_frames = counts.tracked;
  out->uncertain_frames = counts.uncertain;
  out->lost_frames = counts.lost;
  out->relocalisations = counts.relocalisations;
  out->SetReasonText(r.quality.text);
}

void WriteGeometryBuffer(const DepthImage& depth, const Vec3Image& normals,
                         const msgs::Image* image, std::span<const std::byte> image_payload,
                         msgs::GeometryBuffer& out, std::span<std::byte> payload) {
  if (normals.width != depth.width || normals.height != depth.height) {
    throw ReconError("geometry buffer: depth and normals sizes differ");
  }
  out.Init(static_cast<uint32_t>(depth.width), static_cast<uint32_t>(depth.height));
  std::span<float> d = msgs::DepthPlane(out, payload);
  std::span<float> n = msgs::NormalsPlane(out, payload);
  std::span<uint8_t> c = msgs::ColourPlane(out, payload);
  std::memcpy(d.data(), depth.data.data(), d.size_bytes());
  std::memcpy(n.data(), normals.data.data(), n.size_bytes());
  const bool colour =
      image != nullptr && image->width == out.width && image->height == out.height &&
      (image->encoding == msgs::Encoding::kRgb8 || image->encoding == msgs::Encoding::kBgr8 ||
       image->encoding == msgs::Encoding::kMono8) &&
      image_payload.size() >= image->PayloadBytes();
  if (!colour) {
    std::memset(c.data(), 0, c.size());
    return;
  }
  const auto* src = reinterpret_cast<const uint8_t*>(image_payload.data());
  for (uint32_t y = 0; y < out.height; ++y) {
    const uint8_t* row = src + static_cast<size_t>(y) * image->step;
    uint8_t* dst = c.data() + static_cast<size_t>(y) * out.width * 3;
    for (uint32_t x = 0; x < out.width; ++x) {
      if (image->encoding == msgs::Encoding::kMono8) {
        dst[3 * x] = dst[3 * x + 1] = dst[3 * x + 2] = row[x];
      } else if (image->encoding == msgs::Encoding::kRgb8) {
        std::memcpy(dst + 3 * x, row + 3 * x, 3);
      } else {
        dst[3 * x] = row[3 * x + 2];
        dst[3 * x + 1] = row[3 * x + 1];
        dst[3 * x + 2] = row[3 * x];
      }
    }
  }
}

std::vector<AuxiliaryRaycast> RaycastAuxiliaryViews(const TsdfVolume& volume,
                                                    const Pose& camera_to_world, int pixels,
                                                    const Vec3f* light_direction_world,
                                                    ThreadPool* pool) {
  if (pixels < 1 || pixels > static_cast<int>(msgs::kMaxAuxiliaryViewPixels)) {
    throw ReconError("auxiliary views: pixels must be in 1..4096, got " + std::to_string(pixels));
  }
  const AuxiliaryViews lrt = volume.AuxiliaryViewsFor(camera_to_world, pixels);
  std::vector<AuxiliaryRaycast> out(light_direction_world ? 4 : 3);
  out[0].role = msgs::AuxiliaryViewRole::kLeft;
  out[0].view = lrt.left;
  out[1].role = msgs::AuxiliaryViewRole::kRight;
  out[1].view = lrt.right;
  out[2].role = msgs::AuxiliaryViewRole::kTop;
  out[2].view = lrt.top;
  if (light_direction_world) {
    out[3].role = msgs::AuxiliaryViewRole::kLight;
    out[3].view = volume.LightView(*light_direction_world, pixels);
  }
  GeometryView g;
  for (AuxiliaryRaycast& a : out) {
    volume.RaycastOrthographic(a.view, g, pool);
    a.depth = std::move(g.depth);
  }
  return out;
}

Pose AuxiliaryViewToCamera(const Pose& camera_to_world, const OrthographicView& view) {
  return camera_to_world.Inverse() * view.view_to_world;
}

void WriteAuxiliaryViews(const Pose& camera_to_world, const std::vector<AuxiliaryRaycast>& views,
                         msgs::AuxiliaryViews& out, std::span<std::byte> payload) {
  if (views.size() > msgs::kMaxAuxiliaryViews) {
    throw ReconError("auxiliary views: at most 4 views, got " + std::to_string(views.size()));
  }
  out.view_count = static_cast<uint32_t>(views.size());
  for (size_t i = 0; i < views.size(); ++i) {
    const AuxiliaryRaycast& a = views[i];
    if (a.depth.width != a.view.width || a.depth.height != a.view.height) {
      throw ReconError("auxiliary views: view " + std::to_string(i) + " is " +
                       std::to_string(a.view.width) + "x" + std::to_string(a.view.height) +
                       " but its depth " + std::to_string(a.depth.width) + "x" +
                       std::to_string(a.depth.height));
    }
    msgs::AuxiliaryView& v = out.views[i];
    v = {};
    v.role = a.role;
    v.width = static_cast<uint32_t>(a.view.width);
    v.height = static_cast<uint32_t>(a.view.height);
    v.pixel_size_m = a.view.pixel_size_m;
    const Pose v2c = AuxiliaryViewToCamera(camera_to_world, a.view);
    for (int k = 0; k < 9; ++k) v.rotation[k] = static_cast<float>(v2c.r[k]);
    for (int k = 0; k < 3; ++k) v.translation[k] = static_cast<float>(v2c.t[k]);
  }
  for (size_t i = views.size(); i < msgs::kMaxAuxiliaryViews; ++i) out.views[i] = {};
  out.SetStandardLayout();
  if (payload.size() < out.PayloadBytes()) {
    throw ReconError("auxiliary views: payload of " + std::to_string(payload.size()) +
                     " bytes, need " + std::to_string(out.PayloadBytes()));
  }
  for (size_t i = 0; i < views.size(); ++i) {
    std::memcpy(payload.data() + out.views[i].depth_offset, views[i].depth.data.data(),
                out.views[i].DepthPlaneBytes());
  }
}

}  // namespace probeless::recon
