#include "image_io.h"

#include <cstring>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <system_error>

#include "internal.h"

namespace probeless::dataset::internal {

cv::Mat ReadImageFile(const std::string& path, std::string_view what,
                      std::string_view expectation) {
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) {
    throw DatasetError("missing " + std::string(what) + " '" + path + "'");
  }
  cv::Mat decoded;
  try {
    decoded = cv::imread(path, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception&) {
    decoded.release();
  }
  if (decoded.empty()) {
    throw DatasetError("cannot decode " + std::string(what) + " '" + path + "': expected " +
                       std::string(expectation));
  }
  return decoded;
}

msgs::Encoding EncodingForDecoded(const cv::Mat& decoded, const std::string& path) {
  const int depth = decoded.depth();
  const int channels = decoded.channels();
  if (depth == CV_8U && channels == 1) return msgs::Encoding::kMono8;
  if (depth == CV_16U && channels == 1) return msgs::Encoding::kMono16;
  if ((depth == CV_8U || depth == CV_16U) && (channels == 3 || channels == 4)) {
    return msgs::Encoding::kRgb8;
  }
  throw DatasetError("unsupported pixel type in image '" + path + "' (" + DescribeMat(decoded) +
                     "): expected 8- or 16-bit grey or colour");
}

namespace {
cv::Mat To8Bit(const cv::Mat& mat) {
  if (mat.depth() == CV_8U) return mat;
  cv::Mat out;
  mat.convertTo(out, CV_8U, 1.0 / 257.0);
  return out;
}
}  // namespace

cv::Mat ConvertForEncoding(const cv::Mat& decoded, msgs::Encoding encoding,
                           const std::string& path) {
  (void)EncodingForDecoded(decoded, path);  // rejects unsupported pixel types
  const int channels = decoded.channels();
  cv::Mat out;
  switch (encoding) {
    case msgs::Encoding::kRgb8: {
      const cv::Mat eight = To8Bit(decoded);
      const int code = channels == 1   ? cv::COLOR_GRAY2RGB
                       : channels == 3 ? cv::COLOR_BGR2RGB
                                       : cv::COLOR_BGRA2RGB;
      cv::cvtColor(eight, out, code);
      break;
    }
    case msgs::Encoding::kMono8: {
      const cv::Mat eight = To8Bit(decoded);
      if (channels == 1) {
        out = eight;
      } else {
        cv::cvtColor(eight, out, channels == 3 ? cv::COLOR_BGR2GRAY : cv::COLOR_BGRA2GRAY);
      }
      break;
    }
    case msgs::Encoding::kMono16: {
      cv::Mat grey = decoded;
      if (channels != 1) {
        cv::cvtColor(decoded, grey, channels == 3 ? cv::COLOR_BGR2GRAY : cv::COLOR_BGRA2GRAY);
      }
      if (grey.depth() == CV_16U) {
        out = grey;
      } else {
        grey.convertTo(out, CV_16U, 257.0);
      }
      break;
    }
    default:
      throw DatasetError("image '" + path + "': cannot convert to " +
                         std::string(msgs::EncodingName(encoding)));
  }
  if (!out.isContinuous()) out = out.clone();
  return out;
}

std::string DescribeMat(const cv::Mat& mat) {
  const int bits = mat.depth() == CV_8U || mat.depth() == CV_8S     ? 8
                   : mat.depth() == CV_16U || mat.depth() == CV_16S ? 16
                   : mat.depth() == CV_64F                          ? 64
                                                                    : 32;
  return std::to_string(mat.cols) + "x" + std::to_string(mat.rows) + " " + std::to_string(bits) +
         "-bit " + std::to_string(mat.channels()) + "-channel";
}

StreamMessage ImageMessage(size_t topic_index, uint64_t log_time_ns, const cv::Mat& pixels,
                           msgs::Encoding encoding, int64_t stamp_ns, uint64_t sequence,
                           std::string_view frame_id) {
  const auto width = static_cast<uint32_t>(pixels.cols);
  const auto height = static_cast<uint32_t>(pixels.rows);
  StreamMessage message =
      NewMessage(topic_index, log_time_ns, msgs::Image::MessageBytesFor(width, height, encoding));
  msgs::WriteView<msgs::Image> view = msgs::WriteMessage<msgs::Image>(message.message.bytes());
  view->Init(width, height, encoding);
  FillHeader(view->header, stamp_ns, sequence, frame_id);
  const size_t bytes = view->PayloadBytes();
  if (pixels.total() * pixels.elemSize() != bytes || !pixels.isContinuous()) {
    throw std::logic_error("ImageMessage: pixels of " + DescribeMat(pixels) + " do not match " +
                           view->Describe());
  }
  std::memcpy(view.payload.data(), pixels.data, bytes);
  return message;
}

}  // namespace probeless::dataset::internal
