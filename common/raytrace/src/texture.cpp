// Texture files through OpenCV (private).
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "probeless/raytrace/render.h"
#include "probeless/raytrace/scene.h"

namespace probeless::raytrace {

Texture LoadTexture(const std::string& path) {
  const cv::Mat image = cv::imread(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_COLOR);
  if (image.empty()) {
    throw RaytraceError("cannot read texture '" + path +
                        "' (expected an 8-bit PNG/JPEG or a float "
                        "image)");
  }
  Texture t;
  t.width = image.cols;
  t.height = image.rows;
  t.linear_rgb.resize(static_cast<size_t>(t.width) * t.height * 3);
  cv::Mat f;
  if (image.depth() != CV_8U) image.convertTo(f, CV_32FC3);
  for (int y = 0; y < t.height; ++y) {
    for (int x = 0; x < t.width; ++x) {
      float* out = &t.linear_rgb[(static_cast<size_t>(y) * t.width + x) * 3];
      if (image.depth() == CV_8U) {
        const cv::Vec3b p = image.at<cv::Vec3b>(y, x);
        for (int c = 0; c < 3; ++c) out[c] = Srgb8ToLinear(p[2 - c]);
      } else {
        const cv::Vec3f p = f.at<cv::Vec3f>(y, x);
        for (int c = 0; c < 3; ++c) out[c] = p[2 - c];
      }
    }
  }
  return t;
}

}  // namespace probeless::raytrace
