// Conversions between bus messages and the reconstruction's images, with the boundary checks
// (encodings, sizes, intrinsics) the fusion node relies on.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "probeless/msgs/auxiliary_views.h"
#include "probeless/msgs/camera_info.h"
#include "probeless/msgs/geometry_buffer.h"
#include "probeless/msgs/image.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/msgs/tracking_status.h"
#include "probeless/recon/math.h"
#include "probeless/recon/pipeline.h"
#include "probeless/recon/tsdf_volume.h"

namespace probeless::recon {

// Intrinsics of a CameraInfo. Throws ReconError "camera_info: ..." for NaN/inf or non-positive
// focal lengths, a non-positive size, or non-zero lens distortion (rectify first: nodes/rectify).
Intrinsics IntrinsicsFromCameraInfo(const msgs::CameraInfo& info);

// Depth in metres from a depth16 (millimetres; `metres_per_unit` from camera_info.depth_scale,
// 0 -> 0.001) or float32 (metres) image, invalidating values outside [min_m, max_m]. Throws
// ReconError "depth: expected encoding depth16 or float32, got rgb8" for other encodings, for an
// empty image or a payload that does not hold it.
void DepthFromImage(const msgs::Image& image, std::span<const std::byte> payload,
                    double metres_per_unit, float min_m, float max_m, DepthImage& out);

// Grey intensity from an rgb8, bgr8 or mono8 image. Throws ReconError for other encodings, an
// empty image or a short payload.
void GreyFromImage(const msgs::Image& image, std::span<const std::byte> payload, GreyImage& out);

// One depth frame as FusionPipeline::Process takes it: the depth image's header, its depth in
// metres and the intrinsics of the camera_info it came with.
struct DepthFrame {
  msgs::Header header;
  DepthImage depth;
  Intrinsics intrinsics;
};

// The DepthFrame of a depth image and `info`: IntrinsicsFromCameraInfo(info), then
// DepthFromImage with info.depth_scale and [min_m, max_m]. Throws ReconError as those two.
DepthFrame DepthFrameFromMessages(const msgs::Image& depth, std::span<const std::byte> payload,
                                  const msgs::CameraInfo& info, float min_m, float max_m);

// One colour image held for the depth frame with its stamp: the message, a copy of its pixels
// (PayloadBytes(), G_r's colour) and its grey intensity (the merge's guidance).
struct ColourFrame {
  msgs::Image image;
  std::vector<std::byte> payload;
  GreyImage grey;
};

// The ColourFrame of an rgb8, bgr8 or mono8 image. Throws ReconError as GreyFromImage.
ColourFrame ColourFrameFromMessage(const msgs::Image& image, std::span<const std::byte> payload);

// The dominant direction of `light` (in its frame, towards the light), or none when the light has
// none: a squared length not above 1e-6 or not finite.
std::optional<Vec3f> DominantDirection(const msgs::ShLight& light);

// The running frame counts a TrackingStatus carries.
struct TrackingCounts {
  uint64_t frames = 0, tracked = 0, uncertain = 0, lost = 0, relocalisations = 0;
};

// Fills `out` (header left to the caller) with the verdict of `r` (state: kEmpty counts as
// tracked; quality cues, ICP RMS and inlier fraction, integrated, relocalised, the reason text)
// and `counts`.
void FillTrackingStatus(const FrameResult& r, const TrackingCounts& counts,
                        msgs::TrackingStatus* out);

// Fills a GeometryBuffer (Init + planes) of depth.width x depth.height: depth (metres, 0 = none),
// normals (camera frame) and the colour of `image` (rgb8/bgr8/mono8 of the same size, converted to
// RGB) or black when `image` is null or another size. `payload` must hold
// StandardPayloadBytes. Throws ReconError if the sizes of depth and normals differ.
void WriteGeometryBuffer(const DepthImage& depth, const Vec3Image& normals,
                         const msgs::Image* image, std::span<const std::byte> image_payload,
                         msgs::GeometryBuffer& out, std::span<std::byte> payload);

// One raycast auxiliary view (§5.1) of the volume: its role, its geometry (view -> world) and the
// depth along its rays (metres from the view plane, 0 = none).
struct AuxiliaryRaycast {
  msgs::AuxiliaryViewRole role = msgs::AuxiliaryViewRole::kInvalid;
  OrthographicView view;
  DepthImage depth;
};

// The views a G_r of a camera at `camera_to_world` needs: left, right and top
// (TsdfVolume::AuxiliaryViewsFor) and, if `light_direction_world` is given (unit vector towards
// the light, world frame), the light view (TsdfVolume::LightView), each `pixels` square, raycast
// with TsdfVolume::RaycastOrthographic. Throws ReconError for pixels < 1 or > 4096 or a bad
// light direction.
std::vector<AuxiliaryRaycast> RaycastAuxiliaryViews(const TsdfVolume& volume,
                                                    const Pose& camera_to_world, int pixels,
                                                    const Vec3f* light_direction_world,
                                                    ThreadPool* pool);

// view -> camera of an orthographic view for a camera at `camera_to_world`:
// inverse(camera_to_world) * view.view_to_world (the msgs::AuxiliaryView / light::OrthographicView
// contract: p_camera = R p_view + t).
Pose AuxiliaryViewToCamera(const Pose& camera_to_world, const OrthographicView& view);

// Fills `out` (header left to the caller) with up to 4 `views` in the standard layout: roles,
// sizes, pixel sizes, view -> camera (AuxiliaryViewToCamera) and depth planes. `payload` must
// hold out.PayloadBytes() (msgs::AuxiliaryViews::MessageBytesFor(count, pixels, pixels) minus the
// struct). Throws ReconError for more than 4 views, a depth image whose size differs from its
// view's or a payload too small.
void WriteAuxiliaryViews(const Pose& camera_to_world, const std::vector<AuxiliaryRaycast>& views,
                         msgs::AuxiliaryViews& out, std::span<std::byte> payload);

}  // namespace probeless::recon
