// The only translation unit with dlib headers.
#include "dlib_landmarks.h"

#include <dlib/image_processing.h>
#include <dlib/image_processing/frontal_face_detector.h>
#include <dlib/opencv/cv_image.h>

#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <optional>

#include "probeless/face_track/face_tracker.h"

namespace probeless::face_track::internal {

struct DlibLandmarks::Impl {
  dlib::shape_predictor predictor;
  std::optional<dlib::frontal_face_detector> detector;
};

namespace {
dlib::cv_image<unsigned char> Wrap(const GrayView& image) {
  const cv::Mat mat(image.height, image.width, CV_8UC1, const_cast<uint8_t*>(image.data),
                    image.stride);
  return dlib::cv_image<unsigned char>(mat);
}
}  // namespace

DlibLandmarks::DlibLandmarks(const std::string& predictor_path) : impl_(std::make_unique<Impl>()) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(predictor_path, ec)) {
    throw FaceTrackError("shape predictor model '" + predictor_path +
                         "' not found (install the Debian package libdlib-data, or set "
                         "shape_predictor_path)");
  }
  try {
    dlib::deserialize(predictor_path) >> impl_->predictor;
  } catch (const std::exception& e) {
    throw FaceTrackError("shape predictor model '" + predictor_path +
                         "' cannot be read: " + std::string(e.what()).substr(0, 120));
  }
  if (impl_->predictor.num_parts() != kLandmarkCount) {
    throw FaceTrackError("shape predictor model '" + predictor_path + "' has " +
                         std::to_string(impl_->predictor.num_parts()) +
                         " landmarks, expected 68 (iBUG 300-W)");
  }
}

DlibLandmarks::~DlibLandmarks() = default;

std::vector<Box> DlibLandmarks::Detect(const GrayView& image) {
  if (!impl_->detector) impl_->detector = dlib::get_frontal_face_detector();
  std::vector<dlib::rect_detection> found;
  (*impl_->detector)(Wrap(image), found, 0.0);
  std::vector<Box> boxes;
  for (const auto& d : found) {
    boxes.push_back({static_cast<double>(d.rect.left()), static_cast<double>(d.rect.top()),
                     static_cast<double>(d.rect.width()), static_cast<double>(d.rect.height()),
                     d.detection_confidence});
  }
  std::stable_sort(boxes.begin(), boxes.end(),
                   [](const Box& a, const Box& b) { return a.score > b.score; });
  return boxes;
}

std::array<Point2f, kLandmarkCount> DlibLandmarks::Landmarks(const GrayView& image,
                                                             const Box& box) const {
  const dlib::rectangle rect(std::lround(box.x), std::lround(box.y),
                             std::lround(box.x + box.width - 1),
                             std::lround(box.y + box.height - 1));
  const dlib::full_object_detection shape = impl_->predictor(Wrap(image), rect);
  std::array<Point2f, kLandmarkCount> out{};
  for (int i = 0; i < kLandmarkCount; ++i) {
    out[i] = {static_cast<float>(shape.part(i).x()), static_cast<float>(shape.part(i).y())};
  }
  return out;
}

}  // namespace probeless::face_track::internal
