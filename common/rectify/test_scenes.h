// Test-only helpers of the rectify tests (common/rectify and tests/rectify): the Freiburg 1
// camera, the maps that distort an undistorted render, and checkerboard views rendered exactly
// through a distorted lens (per pixel, not by resampling), so rectification can be checked against
// geometry rather than against OpenCV's own remap.
#pragma once

#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <vector>

#include "probeless/msgs/camera_info.h"

namespace probeless::rectify::test {

// The TUM RGB-D Freiburg 1 colour camera (640x480, plumb_bob 0.2624 -0.9531 -0.0054 0.0026 1.1633).
inline msgs::CameraInfo Freiburg1Info() {
  msgs::CameraInfo info;
  info.width = 640;
  info.height = 480;
  info.fx = 517.3;
  info.fy = 516.5;
  info.cx = 318.6;
  info.cy = 255.3;
  info.distortion_model = msgs::DistortionModel::kPlumbBob;
  info.distortion_count = 5;
  const double d[5] = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633};
  for (int i = 0; i < 5; ++i) info.distortion[i] = d[i];
  info.depth_scale = 0.001;
  return info;
}

inline cv::Matx33d K(const msgs::CameraInfo& info) {
  return {info.fx, 0, info.cx, 0, info.fy, info.cy, 0, 0, 1};
}

inline std::vector<double> D(const msgs::CameraInfo& info) {
  return {info.distortion, info.distortion + info.distortion_count};
}

// Normalised undistorted coordinates (x/z, y/z) of distorted pixels `pixels` (iterated to
// convergence, not OpenCV's default 5 iterations).
inline std::vector<cv::Point2d> Undistort(const msgs::CameraInfo& info,
                                          const std::vector<cv::Point2d>& pixels) {
  std::vector<cv::Point2d> out;
  cv::undistortPoints(
      pixels, out, K(info), D(info), cv::noArray(), cv::noArray(),
      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-12));
  return out;
}

// For every pixel of the distorted camera `info`, the pixel of an undistorted image with camera
// matrix `target` (default: info's own K) that it sees: cv::remap(undistorted, distorted, map_x,
// map_y, ...) makes the distorted view (CV_32FC1 maps).
inline void DistortionMaps(const msgs::CameraInfo& info, cv::Mat& map_x, cv::Mat& map_y,
                           const cv::Matx33d* target = nullptr) {
  const cv::Matx33d t = target ? *target : K(info);
  const int w = static_cast<int>(info.width), h = static_cast<int>(info.height);
  std::vector<cv::Point2d> pixels;
  pixels.reserve(static_cast<size_t>(w) * h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) pixels.emplace_back(x, y);
  }
  const std::vector<cv::Point2d> n = Undistort(info, pixels);
  map_x.create(h, w, CV_32FC1);
  map_y.create(h, w, CV_32FC1);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const cv::Point2d& p = n[static_cast<size_t>(y) * w + x];
      map_x.at<float>(y, x) = static_cast<float>(t(0, 0) * p.x + t(0, 2));
      map_y.at<float>(y, x) = static_cast<float>(t(1, 1) * p.y + t(1, 2));
    }
  }
}

// A checkerboard of squares.width x squares.height squares of side `square` metres (one white
// square of margin around it, grey 128 beyond), board frame x along columns, y along rows, z into
// the board, placed by board -> camera (rvec, tvec), seen by `info`'s camera with its distortion
// (distorted = true) or without it: 8-bit grey, 4x4 samples per pixel.
inline cv::Mat RenderBoard(const msgs::CameraInfo& info, cv::Size squares, double square,
                           cv::Vec3d rvec, cv::Vec3d tvec, bool distorted) {
  const int w = static_cast<int>(info.width), h = static_cast<int>(info.height);
  constexpr int kSub = 4;
  std::vector<cv::Point2d> pixels;
  pixels.reserve(static_cast<size_t>(w) * h * kSub * kSub);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      for (int sy = 0; sy < kSub; ++sy) {
        for (int sx = 0; sx < kSub; ++sx) {
          pixels.emplace_back(x + (sx + 0.5) / kSub - 0.5, y + (sy + 0.5) / kSub - 0.5);
        }
      }
    }
  }
  std::vector<cv::Point2d> n;
  if (distorted) {
    n = Undistort(info, pixels);
  } else {
    n.reserve(pixels.size());
    for (const auto& p : pixels)
      n.emplace_back((p.x - info.cx) / info.fx, (p.y - info.cy) / info.fy);
  }
  cv::Matx33d r;
  cv::Rodrigues(rvec, r);
  const cv::Vec3d c0(r(0, 0), r(1, 0), r(2, 0)), c1(r(0, 1), r(1, 1), r(2, 1));
  cv::Mat out(h, w, CV_8UC1);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      double sum = 0;
      for (int s = 0; s < kSub * kSub; ++s) {
        const cv::Point2d& p = n[(static_cast<size_t>(y) * w + x) * kSub * kSub + s];
        // Solve bx c0 + by c1 - t_ray ray = -tvec for the board point on this ray.
        const cv::Vec3d ray(p.x, p.y, 1);
        const cv::Matx33d a(c0[0], c1[0], -ray[0], c0[1], c1[1], -ray[1], c0[2], c1[2], -ray[2]);
        const cv::Vec3d b = a.solve(-tvec, cv::DECOMP_LU);
        const double bx = b[0] / square, by = b[1] / square;
        double value = 128;
        if (b[2] > 0 && bx >= -1 && by >= -1 && bx < squares.width + 1 && by < squares.height + 1) {
          value = 225;
          if (bx >= 0 && by >= 0 && bx < squares.width && by < squares.height &&
              (static_cast<int>(std::floor(bx)) + static_cast<int>(std::floor(by))) % 2 == 0) {
            value = 30;
          }
        }
        sum += value;
      }
      out.at<uint8_t>(y, x) = static_cast<uint8_t>(std::lround(sum / (kSub * kSub)));
    }
  }
  return out;
}

}  // namespace probeless::rectify::test
