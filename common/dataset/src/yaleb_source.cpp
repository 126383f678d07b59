// Extended Yale Face Database B (cropped): yaleBxx/ subject folders of 168x192 8-bit PGMs named
// yaleBxx_P00A±aaaE±ee.pgm by the light's azimuth and elevation.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <numbers>
#include <opencv2/core.hpp>
#include <set>
#include <tuple>

#include "camera_info_file.h"
#include "image_io.h"
#include "internal.h"
#include "probeless/dataset/yaleb.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/sh/sh.h"

namespace probeless::dataset {

namespace {

constexpr std::string_view kFaceExpectation = "an 8-bit grey PGM";
// Guessed focal length of the cropped faces: a face about 16 cm wide fills the 168-pixel crop
// seen from about 1 m (docs/dataset.md).
constexpr double kYaleBFocalPx = 1050;

bool ParseDigits(std::string_view text, size_t count, int& value) {
  if (text.size() < count) return false;
  value = 0;
  for (size_t i = 0; i < count; ++i) {
    if (text[i] < '0' || text[i] > '9') return false;
    value = value * 10 + (text[i] - '0');
  }
  return true;
}

bool ParseSigned(std::string_view text, size_t digits, int& value) {
  if (text.empty() || (text[0] != '+' && text[0] != '-')) return false;
  if (!ParseDigits(text.substr(1), digits, value)) return false;
  if (text[0] == '-') value = -value;
  return true;
}

}  // namespace

std::optional<YaleBName> ParseYaleBName(std::string_view name) {
  // yaleB01_P00A+000E+00.pgm: 5 + 2 + 5 + 4 + 1 + 3 + 4 characters.
  if (name.size() != 24 || !name.starts_with("yaleB") || name.substr(7, 5) != "_P00A" ||
      name[16] != 'E' || name.substr(20) != ".pgm") {
    return std::nullopt;
  }
  YaleBName parsed;
  if (!ParseDigits(name.substr(5, 2), 2, parsed.subject) ||
      !ParseSigned(name.substr(12, 4), 3, parsed.azimuth_deg) ||
      !ParseSigned(name.substr(17, 3), 2, parsed.elevation_deg)) {
    return std::nullopt;
  }
  return parsed;
}

std::array<double, 3> YaleBLightDirection(double azimuth_deg, double elevation_deg) {
  constexpr double kDeg = std::numbers::pi / 180;
  return sh::DirectionFromAzimuthElevation(azimuth_deg * kDeg, elevation_deg * kDeg);
}

namespace internal {

namespace {

struct FaceImage {
  YaleBName name;
  std::string file;
};

class YaleBSource : public FrameSource {
 public:
  YaleBSource(const std::string& path, const DatasetOptions& options, std::vector<FaceImage> images,
              Intrinsics intrinsics, cv::Size size)
      : FrameSource("yaleb", path, images.size()),
        options_(options),
        images_(std::move(images)),
        intrinsics_(std::move(intrinsics)),
        size_(size) {
    const uint64_t n = images_.size();
    info_topic_ = AddTopic<msgs::CameraInfo>(TopicName(options.topic_prefix, "camera_info"),
                                             sizeof(msgs::CameraInfo), n);
    image_topic_ = AddTopic<msgs::Image>(
        TopicName(options.topic_prefix, "image"),
        msgs::Image::MessageBytesFor(size.width, size.height, msgs::Encoding::kMono8), n);
    light_topic_ = AddTopic<msgs::ShLight>(TopicName(options.ground_truth_prefix, "light"),
                                           sizeof(msgs::ShLight), n);
    time_range_ = std::make_pair(uint64_t{0}, FrameTimeNs(n - 1, options.fps));
  }

 protected:
  bool ReadFrame(uint64_t index, std::vector<StreamMessage>& out) override {
    if (index >= images_.size()) return false;
    const FaceImage& face = images_[index];
    const uint64_t time = FrameTimeNs(index, options_.fps);
    const auto stamp = static_cast<int64_t>(time);
    const uint64_t sequence = index + 1;
    const std::string& frame_id = options_.camera_frame_id;

    cv::Mat pixels = ReadImageFile(face.file, "Yale B image", kFaceExpectation);
    if (pixels.type() != CV_8UC1 || pixels.size() != size_) {
      throw DatasetError("Yale B image '" + face.file + "' is " + DescribeMat(pixels) +
                         ": expected an 8-bit grey " + std::to_string(size_.width) + "x" +
                         std::to_string(size_.height) + " PGM like the first image");
    }
    if (!pixels.isContinuous()) pixels = pixels.clone();

    out.push_back(CameraInfoMessage(info_topic_, time, intrinsics_, 0, stamp, sequence, frame_id));
    out.push_back(ImageMessage(image_topic_, time, pixels, msgs::Encoding::kMono8, stamp, sequence,
                               frame_id));

    StreamMessage message = NewMessage(light_topic_, time, sizeof(msgs::ShLight));
    msgs::WriteView<msgs::ShLight> light =
        msgs::WriteMessage<msgs::ShLight>(message.message.bytes());
    FillHeader(light->header, stamp, sequence, frame_id);
    const std::array<double, 3> d =
        YaleBLightDirection(face.name.azimuth_deg, face.name.elevation_deg);
    // A directional light of radiance integral 1: the basis at its direction (sh.h).
    const std::array<double, 9> coefficients = sh::Basis9(d);
    light->bands = 3;
    for (size_t i = 0; i < coefficients.size(); ++i) {
      for (int c = 0; c < 3; ++c) light->coefficients[i][c] = static_cast<float>(coefficients[i]);
    }
    for (int k = 0; k < 3; ++k) light->dominant_direction[k] = static_cast<float>(d[k]);
    light->intensity = 1;
    light->confidence = 1;
    light->units = msgs::ShLightUnits::kLinearUnscaled;  // a unit light: its scale is unknown
    out.push_back(std::move(message));
    return true;
  }

 private:
  DatasetOptions options_;
  std::vector<FaceImage> images_;
  Intrinsics intrinsics_;
  cv::Size size_;
  size_t info_topic_ = 0;
  size_t image_topic_ = 0;
  size_t light_topic_ = 0;
};

bool IsSubjectFolderName(const std::string& name) {
  return name.size() == 7 && name.starts_with("yaleB") && std::isdigit(name[5]) &&
         std::isdigit(name[6]);
}

void Collect(const std::string& dir, std::vector<FaceImage>& images) {
  for (const std::string& name : ListFiles(dir)) {
    if (const std::optional<YaleBName> parsed = ParseYaleBName(name)) {
      images.push_back({*parsed, JoinPath(dir, name)});
    }
  }
}

std::string SubjectName(int subject) {
  return std::string("yaleB") + (subject < 10 ? "0" : "") + std::to_string(subject);
}

}  // namespace

std::unique_ptr<Source> OpenYaleB(const std::string& path, const DatasetOptions& options) {
  std::vector<FaceImage> images;
  Collect(path, images);
  for (const std::string& folder : ListFolders(path)) {
    if (IsSubjectFolderName(folder)) Collect(JoinPath(path, folder), images);
  }
  if (!options.yaleb_subjects.empty()) {
    const std::set<int> wanted(options.yaleb_subjects.begin(), options.yaleb_subjects.end());
    for (int subject : wanted) {
      const bool found = std::any_of(images.begin(), images.end(),
                                     [&](const FaceImage& f) { return f.name.subject == subject; });
      if (!found) {
        throw DatasetError("Yale B folder '" + path + "' has no images of subject " +
                           SubjectName(subject));
      }
    }
    std::erase_if(images, [&](const FaceImage& f) { return !wanted.contains(f.name.subject); });
  }
  if (images.empty()) {
    throw DatasetError("Yale B folder '" + path +
                       "' has no yaleBxx_P00A±aaaE±ee.pgm images (nor yaleBxx/ folders with them)");
  }
  std::sort(images.begin(), images.end(), [](const FaceImage& a, const FaceImage& b) {
    return std::tie(a.name.subject, a.name.azimuth_deg, a.name.elevation_deg, a.file) <
           std::tie(b.name.subject, b.name.azimuth_deg, b.name.elevation_deg, b.file);
  });
  images.resize(LimitFrames(images.size(), options));

  const cv::Mat first = ReadImageFile(images.front().file, "Yale B image", kFaceExpectation);
  if (first.type() != CV_8UC1) {
    throw DatasetError("Yale B image '" + images.front().file + "' is " + DescribeMat(first) +
                       ": expected " + std::string(kFaceExpectation));
  }
  Intrinsics guess;
  guess.fx = kYaleBFocalPx;
  guess.fy = kYaleBFocalPx;
  guess.cx = (first.cols - 1) / 2.0;
  guess.cy = (first.rows - 1) / 2.0;
  const Intrinsics intrinsics = ResolveIntrinsics(options, guess, static_cast<uint32_t>(first.cols),
                                                  static_cast<uint32_t>(first.rows));
  return std::make_unique<YaleBSource>(path, options, std::move(images), intrinsics, first.size());
}

}  // namespace internal
}  // namespace probeless::dataset
