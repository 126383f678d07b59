// Bus-message adapters of probeless_light: msgs::GeometryBuffer + CameraInfo -> GeometryView,
// a raw depth16 image -> a G-buffer (the node's `depth` mode), the messages of one frame ->
// ScenePipeline's SceneFrame (SceneFrameBuilder), results -> msgs::ShLight,
// msgs::TransferBuffer and the indirect buffer as an rgb32f msgs::Image. Errors are LightError /
// msgs::MessageError with one line.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "probeless/light/estimate.h"
#include "probeless/light/pipeline.h"
#include "probeless/light/reliability.h"
#include "probeless/light/transfer.h"
#include "probeless/msgs/auxiliary_views.h"
#include "probeless/msgs/camera_info.h"
#include "probeless/msgs/geometry.h"
#include "probeless/msgs/geometry_buffer.h"
#include "probeless/msgs/image.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/msgs/transfer_buffer.h"

namespace probeless::light {

// Intrinsics of `info`; throws LightError if they are not finite or fx, fy <= 0 ("NaN
// intrinsics"), or if `width` x `height` differ from the calibration's size.
Intrinsics IntrinsicsFrom(const msgs::CameraInfo& info, int width, int height);

// A view borrowing the planes of `g` (payload of its sample) with `info`'s intrinsics. Throws
// msgs::MessageError for an invalid buffer and LightError for a size mismatch with `info`, bad
// intrinsics or a buffer without any normal where there is depth ("missing normals").
GeometryView ViewOfGeometryBuffer(const msgs::GeometryBuffer& g, std::span<const std::byte> payload,
                                  const msgs::CameraInfo& info);

// The auxiliary views of a msgs::AuxiliaryViews message (the OrthographicView contract is the
// message's), borrowing its depth planes from `payload` (the sample's). Throws msgs::MessageError
// (one line) for a malformed message.
AuxiliaryBuffers AuxiliaryFromMessage(const msgs::AuxiliaryViews& message,
                                      std::span<const std::byte> payload);

// The depth in metres (width x height of `depth`, 0 = none) of a depth16 image (depth_scale of
// `info`, 0.001 when unset) or a float32 one (metres; non-finite and <= 0 -> 0): the input of
// ScenePipeline's depth image. Throws LightError for another encoding or a size other than
// `info`'s.
void DepthFromImage(const msgs::Image& depth, std::span<const std::byte> payload,
                    const msgs::CameraInfo& info, std::vector<float>* depth_m);

// A G-buffer from a depth16 (or float32 metres) image: depth in metres (depth_scale of `info`,
// 0.001 when unset for depth16) and normals by DepthGeometry (`options`; default kAuto: a clean
// image gets edge-aware normals, unsmoothed, step width / 320; a Kinect-like one is smoothed
// (radius width / 80) and gets central differences (step max(2, width / 160))) — the returned
// depth is the smoothed one — and, if `reliability` is given, the normals' reliability. Throws
// LightError for another encoding, a size mismatch or bad intrinsics.
void GeometryFromDepthImage(const msgs::Image& depth, std::span<const std::byte> payload,
                            const msgs::CameraInfo& info, std::vector<float>* depth_m,
                            std::vector<float>* normals, const DepthGeometryOptions& options = {},
                            std::vector<float>* reliability = nullptr);

// Linear grey intensity of an rgb8 / bgr8 / mono8 image into `grey` (width * height) and, if `rgb`
// is given, the sRGB bytes in R, G, B order (3 per pixel; cleared for mono8) for EstimateLight's
// albedo groups. Throws LightError for a size other than width x height and msgs::MessageError for
// an encoding without byte channels (all but rgb8 / bgr8 / mono8).
void GreyFromImage(const msgs::Image& image, std::span<const std::byte> payload, int width,
                   int height, std::vector<float>* grey, std::vector<uint8_t>* rgb = nullptr);

// The SceneFrame of one frame's messages (scene_light's conversion): the geometry from the
// triggering message (a G_r or a depth image), then I_c from the latest camera image and, for the
// shadow search on a G_r, the depth image with its stamp. Units and frames are SceneFrame's:
// depth in metres along the camera's z, normals in the camera frame, intrinsics in pixels of
// `info` (which must be the size of the geometry). It owns the scratch buffers (grey, RGB bytes,
// depths in metres) and reuses them from frame to frame: a frame borrows them (and the G_r's
// payload) until the builder's next call of the same method. The aux views, focus and camera
// rotation are left to the caller. Not thread-safe.
class SceneFrameBuilder {
 public:
  // A frame with G_r's geometry (SceneGeometrySource::kGeometryBuffer): size, intrinsics of
  // `info`, depth, normals and colour borrowed from `payload` (ViewOfGeometryBuffer), the stamp
  // of g's header; no image yet. Throws as ViewOfGeometryBuffer.
  SceneFrame FromGeometryBuffer(const msgs::GeometryBuffer& g, std::span<const std::byte> payload,
                                const msgs::CameraInfo& info);
  // A frame with a depth image's geometry (SceneGeometrySource::kDepthImage): size, intrinsics
  // of `info`, depth_image in metres (DepthFromImage: depth16 x depth_scale, float32 as is), the
  // stamp of its header; no image yet. Throws as DepthFromImage and IntrinsicsFrom.
  SceneFrame FromDepthImage(const msgs::Image& depth, std::span<const std::byte> payload,
                            const msgs::CameraInfo& info);
  // Sets `frame`'s grey (linear, width * height) and colour (sRGB bytes in R, G, B order; empty
  // for mono8) from `image` (GreyFromImage). Throws LightError for a size other than the frame's
  // and msgs::MessageError for an encoding without byte channels (all but rgb8 / bgr8 / mono8).
  void AddImage(const msgs::Image& image, std::span<const std::byte> payload, SceneFrame* frame);
  // Sets `frame`'s depth_image (the shadow search's geometry on a G_r) to `depth` in metres
  // (DepthFromImage with `info`). Throws LightError for a size other than the frame's and as
  // DepthFromImage.
  void AddShadowDepth(const msgs::Image& depth, std::span<const std::byte> payload,
                      const msgs::CameraInfo& info, SceneFrame* frame);

 private:
  std::vector<float> grey_;
  std::vector<uint8_t> rgb_;
  std::vector<float> depth_;         // FromDepthImage's geometry, metres
  std::vector<float> shadow_depth_;  // AddShadowDepth's, metres
};

// Fills `out` (header left to the caller) with the white light of `e`: every channel gets the
// same coefficients (bands = min(e.bands, 5)), scaled by `scale`; direction, intensity,
// confidence; units msgs::ShLightUnits::kLinear (the estimate is in the image's linear units).
void FillShLight(const LightEstimate& e, msgs::ShLight* out, float scale = 1.0f);

// The rotation of `camera_to_world` (child -> parent, msgs::Pose::transform) as a row-major 3 x 3
// matrix R (d_parent = R d_camera) of the normalised quaternion: SceneFrame's
// camera_to_world_rotation. Throws LightError for a quaternion of norm 0 or not finite.
std::array<double, 9> CameraToWorldRotation(const msgs::RigidTransform& camera_to_world);

// The point `world` (metres, in camera_to_world's parent frame) in the camera frame of
// `camera_to_world` (child -> parent, msgs::Pose::transform): R^T (world - t), R of the
// normalised quaternion. Throws LightError for a quaternion of norm 0 or not finite.
std::array<float, 3> WorldPointInCamera(const msgs::RigidTransform& camera_to_world,
                                        const std::array<double, 3>& world);

// Writes the one-bounce indirect buffer of `result` (TransferResult::indirect, eq. 10-12: linear
// RGB radiance towards the camera for albedo 1, 0 where no surface) into `out` as an rgb32f image
// of result.width x result.height (header left to the caller); `payload` is the message's payload
// and must hold msgs::Image::PackedPayloadBytes(width, height, kRgb32f). Throws LightError if
// `result` has no indirect buffer (Compute got no DominantLight) or the payload is too small.
void FillIndirectImage(const TransferResult& result, msgs::Image* out,
                       std::span<std::byte> payload);

}  // namespace probeless::light
