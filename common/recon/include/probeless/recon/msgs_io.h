// Conversions between bus messages and the reconstruction's images, with the boundary checks
// (encodings, sizes, intrinsics) the fusion node relies on.
#pragma once

#include <cstddef>
#include <span>

#include "probeless/msgs/camera_info.h"
#include "probeless/msgs/geometry_buffer.h"
#include "probeless/msgs/image.h"
#include "probeless/recon/math.h"

namespace probeless::recon {

// Intrinsics of a CameraInfo. Throws ReconError "camera_info: ..." for NaN/inf or non-positive
// focal lengths, a non-positive size, or lens distortion other than none (rectify first).
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

// Fills a GeometryBuffer (Init + planes) of depth.width x depth.height: depth (metres, 0 = none),
// normals (camera frame) and the colour of `image` (rgb8/bgr8/mono8 of the same size, converted to
// RGB) or black when `image` is null or another size. `payload` must hold
// StandardPayloadBytes. Throws ReconError if the sizes of depth and normals differ.
void WriteGeometryBuffer(const DepthImage& depth, const Vec3Image& normals,
                         const msgs::Image* image, std::span<const std::byte> image_payload,
                         msgs::GeometryBuffer& out, std::span<std::byte> payload);

}  // namespace probeless::recon
