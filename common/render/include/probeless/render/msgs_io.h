// Conversions between bus messages (msgs/) and the renderer's inputs and outputs.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "probeless/light/transfer.h"
#include "probeless/msgs/camera_info.h"
#include "probeless/msgs/geometry.h"
#include "probeless/msgs/geometry_buffer.h"
#include "probeless/msgs/image.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/msgs/transfer_buffer.h"
#include "probeless/render/renderer.h"

namespace probeless::render {

// The light's RGB coefficients. Throws RenderError if the message fails ShLight::Validate.
ShLightRgb LightFromMsg(const msgs::ShLight& light);
// The dominant light of eq. 10 (the differential's indirect term and crisp shadow) of a light
// that passed ShLight::Validate: the message's own dominant_direction and intensity when it has
// them (intensity > 0 and a direction of squared length > 0.5), else Sloan's optimal linear
// direction of the mean of R, G, B (sh::OptimalLinearDirection) and sh::DirectionalPower along
// it, clamped to >= 0; none (zero direction and intensity) below 2 bands or without band 1.
light::DominantLight DominantLightFromMsg(const msgs::ShLight& light);
// Whether the renderer shades with a light of `units` (it needs linear radiance in the camera's
// units): kLinear yes; kUnknown (a message recorded before the units field) and kLinearUnscaled
// yes, taken as linear, with `*warning` set to one line saying so; kFaceModel (and any other
// value) no, `*warning` saying why. `*warning` is cleared for kLinear.
bool AcceptLightUnits(msgs::ShLightUnits units, std::string* warning);
// A rigid transform (unit quaternion w, x, y, z). Throws RenderError for a zero quaternion.
raytrace::Transform TransformFromMsg(const msgs::RigidTransform& transform);
// Intrinsics of a calibration (distortion ignored). Throws RenderError for invalid values.
Intrinsics IntrinsicsFromMsg(const msgs::CameraInfo& info);
// Default intrinsics for an image without calibration: f = 525 * width / 640, centred.
Intrinsics DefaultIntrinsics(int width, int height);
// An rgb8, bgr8 or mono8 image as packed rgb8 (width * height * 3). Throws RenderError for other
// encodings or a payload that fails Image::Validate.
void ImageToRgb(const msgs::Image& image, std::span<const std::byte> payload,
                std::vector<uint8_t>& rgb);
// The depth plane of a geometry buffer (metres). Throws RenderError if it fails Validate.
void GeometryDepth(const msgs::GeometryBuffer& g, std::span<const std::byte> payload,
                   std::vector<float>& depth);
// The normals (3 per pixel, camera frame) and colour (sRGB, 3 per pixel) planes of a geometry
// buffer. Throws RenderError if it fails Validate.
void GeometryPlanes(const msgs::GeometryBuffer& g, std::span<const std::byte> payload,
                    std::vector<float>& normals, std::vector<uint8_t>& colour);
// The coefficients of a transfer buffer (interleaved). Throws RenderError if it fails Validate.
void TransferValues(const msgs::TransferBuffer& t, std::span<const std::byte> payload,
                    std::vector<float>& values);

}  // namespace probeless::render
