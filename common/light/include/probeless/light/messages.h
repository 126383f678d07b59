// Bus-message adapters of probeless_light: msgs::GeometryBuffer + CameraInfo -> GeometryView,
// a raw depth16 image -> a G-buffer (the node's `depth` mode), results -> msgs::ShLight,
// msgs::TransferBuffer and the indirect buffer as an rgb32f msgs::Image. Errors are LightError /
// msgs::MessageError with one line.
#pragma once

#include <array>
#include <cstddef>
#include <span>
#include <vector>

#include "probeless/light/estimate.h"
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
// albedo groups. Throws LightError for another encoding or a size other than width x height.
void GreyFromImage(const msgs::Image& image, std::span<const std::byte> payload, int width,
                   int height, std::vector<float>* grey, std::vector<uint8_t>* rgb = nullptr);

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
