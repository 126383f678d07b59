// JPEG compression of images for the bridge's "<topic>/compressed" channels
// (sensor_msgs/msg/CompressedImage, format "jpeg"), with libjpeg-turbo (private).
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "probeless/log/cdr.h"

namespace probeless::foxglove {

// The JPEG (baseline, 4:2:0 for colour) of a whole bus message of type msgs::Image (struct then
// payload) in rgb8, bgr8 or mono8, at `quality` 1..100. Throws FoxgloveError for another
// encoding, a quality out of range or an image that fails msgs::Image::Validate.
std::vector<std::byte> EncodeJpeg(std::span<const std::byte> image_message, int quality);

// The CDR of the sensor_msgs/msg/CompressedImage of that JPEG (the image's header, "jpeg") into
// `out` (Reset first). Same errors.
void EncodeCompressedImageCdr(std::span<const std::byte> image_message, int quality,
                              log::CdrWriter& out);

}  // namespace probeless::foxglove
