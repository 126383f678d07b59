// Golden-image comparison of the end-to-end tests: composites are compared with committed PNGs
// (tests/e2e/golden/) at a reduced size, by the mean absolute difference over the whole picture
// and the largest mean absolute difference of any small block. The block term catches a wrong
// or missing virtual object (a few percent of the picture) that the global mean would average
// away; both limits sit well above the run-to-run variation of the graph (docs/replay.md,
// "End-to-end tests") and below what a missing object or a 20 % wrong light produces
// (GoldenCompare tests).
#pragma once

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

namespace probeless::e2e {

// Golden images are this wide (height keeps the aspect ratio); area-averaged from the composite.
inline constexpr int kGoldenWidth = 160;
// Side of the square blocks (pixels of the golden size) whose mean difference is bounded.
inline constexpr int kBlockSize = 4;
// Limits, in 8-bit levels (0..255) of the channel that differs most at each pixel.
inline constexpr double kMaxMeanAbsDiff = 1.5;
// The block limit leaves room for the machine: Embree's and the dispatched kernels' ISA paths
// (AVX2 or AVX-512) round differently and move a few pixels at a crisp shadow edge
// (docs/replay.md).
inline constexpr double kMaxBlockMeanAbsDiff = 10.0;

struct ImageDiff {
  double mean_abs = 0;        // over every pixel (largest channel difference)
  double max_block_mean = 0;  // largest mean over a kBlockSize x kBlockSize block
  bool Matches() const {
    return mean_abs <= kMaxMeanAbsDiff && max_block_mean <= kMaxBlockMeanAbsDiff;
  }
};

// `image` (8-bit, 3 channels) area-averaged to kGoldenWidth wide.
inline cv::Mat ToGoldenSize(const cv::Mat& image) {
  if (image.empty() || image.type() != CV_8UC3) {
    throw std::invalid_argument("golden: expected a non-empty 8-bit 3-channel image");
  }
  const int height = std::max(1, (image.rows * kGoldenWidth + image.cols / 2) / image.cols);
  cv::Mat small;
  cv::resize(image, small, cv::Size(kGoldenWidth, height), 0, 0, cv::INTER_AREA);
  return small;
}

// Differences of two images of the golden size (same size and type, 8-bit 3 channels).
inline ImageDiff Compare(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != CV_8UC3 || b.type() != CV_8UC3) {
    throw std::invalid_argument("golden: images differ in size or type (expected two " +
                                std::to_string(b.cols) + "x" + std::to_string(b.rows) +
                                " 8-bit 3-channel images)");
  }
  cv::Mat diff;
  cv::absdiff(a, b, diff);
  cv::Mat channels[3];  // the largest difference of the three channels per pixel, as float
  cv::split(diff, channels);
  cv::Mat grey = cv::max(cv::max(channels[0], channels[1]), channels[2]);
  grey.convertTo(grey, CV_32F);
  ImageDiff d;
  d.mean_abs = cv::mean(grey)[0];
  for (int y = 0; y < grey.rows; y += kBlockSize) {
    for (int x = 0; x < grey.cols; x += kBlockSize) {
      const cv::Rect block(x, y, std::min(kBlockSize, grey.cols - x),
                           std::min(kBlockSize, grey.rows - y));
      d.max_block_mean = std::max(d.max_block_mean, cv::mean(grey(block))[0]);
    }
  }
  return d;
}

}  // namespace probeless::e2e
