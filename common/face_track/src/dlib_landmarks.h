// Internal: dlib's HOG face detector and 68-point shape predictor behind a dlib-free interface
// (dlib headers stay in dlib_landmarks.cpp).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "probeless/face_track/head_model.h"

namespace probeless::face_track::internal {

// x, y, width, height in pixels (x, y = top-left corner), and a detector score.
struct Box {
  double x = 0, y = 0, width = 0, height = 0, score = 0;
};

// An 8-bit gray image (not owned).
struct GrayView {
  const uint8_t* data = nullptr;
  int width = 0;
  int height = 0;
  size_t stride = 0;
};

class DlibLandmarks {
 public:
  // Loads the shape predictor (throws FaceTrackError naming the path and libdlib-data); the HOG
  // detector is built on first use of Detect.
  explicit DlibLandmarks(const std::string& predictor_path);
  ~DlibLandmarks();
  // HOG detections (no upsampling), highest score first.
  std::vector<Box> Detect(const GrayView& image);
  // The 68 landmarks inside `box` (pixels).
  std::array<Point2f, kLandmarkCount> Landmarks(const GrayView& image, const Box& box) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace probeless::face_track::internal
