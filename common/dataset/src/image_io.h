// Private: image decoding with OpenCV and conversion into probeless Image messages.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <string_view>

#include "probeless/dataset/source.h"
#include "probeless/msgs/image.h"

namespace probeless::dataset::internal {

// The decoded file (cv::IMREAD_UNCHANGED: bit depth and channels as stored). Throws DatasetError
// "missing <what> '<path>'" or "cannot decode <what> '<path>': expected <expectation>".
cv::Mat ReadImageFile(const std::string& path, std::string_view what, std::string_view expectation);

// The encoding a decoded image is published in: mono8 (8-bit grey), mono16 (16-bit grey), rgb8
// (colour, any depth; alpha dropped). Throws DatasetError naming `path` for other pixel types.
msgs::Encoding EncodingForDecoded(const cv::Mat& decoded, const std::string& path);

// `decoded` converted to `encoding` (rgb8, mono8 or mono16) as a continuous CV_8UC3 (R, G, B),
// CV_8UC1 or CV_16UC1 matrix: colour <-> grey by OpenCV's BGR<->grey conversion, 8 <-> 16 bits by
// x * 257 and round(x / 257). Throws DatasetError naming `path` for unsupported pixel types.
cv::Mat ConvertForEncoding(const cv::Mat& decoded, msgs::Encoding encoding,
                           const std::string& path);

// "640x480 8-bit 3-channel" for messages.
std::string DescribeMat(const cv::Mat& mat);

// A new Image message on `topic_index` at `log_time_ns` holding `pixels` (continuous, already in
// the layout of `encoding`, tightly packed), stamped `stamp_ns`, `sequence`, `frame_id`.
StreamMessage ImageMessage(size_t topic_index, uint64_t log_time_ns, const cv::Mat& pixels,
                           msgs::Encoding encoding, int64_t stamp_ns, uint64_t sequence,
                           std::string_view frame_id);

}  // namespace probeless::dataset::internal
