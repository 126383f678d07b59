// A folder of still images (png, jpg, jpeg, pgm, ppm, bmp) played in file-name order at a fixed
// rate.
#include <opencv2/core.hpp>

#include "camera_info_file.h"
#include "image_io.h"
#include "internal.h"

namespace probeless::dataset::internal {

namespace {

constexpr std::string_view kImageExpectation = "a png, jpg, pgm, ppm or bmp image";

class ImagesSource : public FrameSource {
 public:
  ImagesSource(const std::string& path, const DatasetOptions& options,
               std::vector<std::string> files, msgs::Encoding encoding, Intrinsics intrinsics,
               cv::Size size)
      : FrameSource("images", path, files.size()),
        options_(options),
        files_(std::move(files)),
        encoding_(encoding),
        intrinsics_(std::move(intrinsics)),
        size_(size) {
    const uint64_t n = files_.size();
    info_topic_ = AddTopic<msgs::CameraInfo>(TopicName(options.topic_prefix, "camera_info"),
                                             sizeof(msgs::CameraInfo), n);
    image_topic_ =
        AddTopic<msgs::Image>(TopicName(options.topic_prefix, "image"),
                              msgs::Image::MessageBytesFor(size.width, size.height, encoding), n);
    time_range_ = std::make_pair(uint64_t{0}, FrameTimeNs(n - 1, options.fps));
  }

 protected:
  bool ReadFrame(uint64_t index, std::vector<StreamMessage>& out) override {
    if (index >= files_.size()) return false;
    const std::string& file = files_[index];
    const uint64_t time = FrameTimeNs(index, options_.fps);
    const auto stamp = static_cast<int64_t>(time);
    const cv::Mat decoded = ReadImageFile(file, "image", kImageExpectation);
    if (decoded.size() != size_) {
      throw DatasetError("image '" + file + "' is " + DescribeMat(decoded) + ": expected " +
                         std::to_string(size_.width) + "x" + std::to_string(size_.height) +
                         " like the first image of the folder");
    }
    const cv::Mat pixels = ConvertForEncoding(decoded, encoding_, file);
    out.push_back(CameraInfoMessage(info_topic_, time, intrinsics_, 0, stamp, index + 1,
                                    options_.camera_frame_id));
    out.push_back(ImageMessage(image_topic_, time, pixels, encoding_, stamp, index + 1,
                               options_.camera_frame_id));
    return true;
  }

 private:
  DatasetOptions options_;
  std::vector<std::string> files_;
  msgs::Encoding encoding_;
  Intrinsics intrinsics_;
  cv::Size size_;
  size_t info_topic_ = 0;
  size_t image_topic_ = 0;
};

}  // namespace

bool IsImageFileName(const std::string& name) {
  const std::string ext = LowerExtension(name);
  return ext == "png" || ext == "jpg" || ext == "jpeg" || ext == "pgm" || ext == "ppm" ||
         ext == "bmp";
}

std::unique_ptr<Source> OpenImages(const std::string& path, const DatasetOptions& options) {
  std::vector<std::string> files;
  for (const std::string& name : ListFiles(path)) {
    if (IsImageFileName(name)) files.push_back(JoinPath(path, name));
  }
  if (files.empty()) {
    throw DatasetError("image folder '" + path + "' has no png, jpg, jpeg, pgm, ppm or bmp files");
  }
  files.resize(LimitFrames(files.size(), options));
  const cv::Mat first = ReadImageFile(files.front(), "image", kImageExpectation);
  const msgs::Encoding encoding = EncodingForDecoded(first, files.front());
  const auto width = static_cast<uint32_t>(first.cols);
  const auto height = static_cast<uint32_t>(first.rows);
  const Intrinsics intrinsics =
      ResolveIntrinsics(options, calib::IntrinsicsFromFieldOfView(width, height), width, height);
  return std::make_unique<ImagesSource>(path, options, std::move(files), encoding, intrinsics,
                                        first.size());
}

}  // namespace probeless::dataset::internal
