#include "probeless/render/output.h"

#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

namespace probeless::render {

namespace {
cv::Mat ToBgr(int width, int height, std::span<const uint8_t> rgb) {
  if (rgb.size() != static_cast<size_t>(width) * height * 3) {
    throw RenderError("image: " + std::to_string(rgb.size()) + " bytes for " +
                      std::to_string(width) + "x" + std::to_string(height) + " rgb8");
  }
  cv::Mat view(height, width, CV_8UC3, const_cast<uint8_t*>(rgb.data()));
  cv::Mat bgr;
  cv::cvtColor(view, bgr, cv::COLOR_RGB2BGR);
  return bgr;
}
}  // namespace

void WritePng(const std::string& path, int width, int height, std::span<const uint8_t> rgb) {
  const cv::Mat bgr = ToBgr(width, height, rgb);
  bool ok = false;
  try {
    ok = cv::imwrite(path, bgr);
  } catch (const cv::Exception&) {
  }
  if (!ok) throw RenderError("cannot write image '" + path + "'");
}

std::vector<uint8_t> ReadImageRgb(const std::string& path, int& width, int& height) {
  const cv::Mat bgr = cv::imread(path, cv::IMREAD_COLOR);
  if (bgr.empty()) throw RenderError("cannot read image '" + path + "'");
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  width = rgb.cols;
  height = rgb.rows;
  return std::vector<uint8_t>(rgb.data, rgb.data + rgb.total() * 3);
}

struct FrameWriter::Impl {
  std::string video_path;
  double fps = 30;
  std::string png_dir;
  cv::VideoWriter video;
  int width = 0, height = 0;
  size_t frames = 0;
};

FrameWriter::FrameWriter(const std::string& video_path, double fps, const std::string& png_dir)
    : impl_(std::make_unique<Impl>()) {
  impl_->video_path = video_path;
  impl_->fps = fps > 0 ? fps : 30;
  impl_->png_dir = png_dir;
  if (!png_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(png_dir, ec);
    if (ec || !std::filesystem::is_directory(png_dir)) {
      throw RenderError("cannot create PNG directory '" + png_dir + "'");
    }
  }
}

FrameWriter::~FrameWriter() = default;

void FrameWriter::Write(const Composite& frame) {
  Impl& m = *impl_;
  const cv::Mat bgr = ToBgr(frame.width, frame.height, frame.rgb);
  if (!m.video_path.empty()) {
    if (!m.video.isOpened()) {
      const std::string ext = std::filesystem::path(m.video_path).extension().string();
      const int fourcc = ext == ".mp4" ? cv::VideoWriter::fourcc('m', 'p', '4', 'v')
                                       : cv::VideoWriter::fourcc('M', 'J', 'P', 'G');
      m.video.open(m.video_path, fourcc, m.fps, cv::Size(frame.width, frame.height));
      if (!m.video.isOpened()) throw RenderError("cannot open video '" + m.video_path + "'");
      m.width = frame.width;
      m.height = frame.height;
    }
    if (frame.width != m.width || frame.height != m.height) {
      throw RenderError("video '" + m.video_path + "': frame size changed");
    }
    m.video.write(bgr);
  }
  ++m.frames;
  if (!m.png_dir.empty()) {
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%06zu.png", m.frames);
    const std::string path = (std::filesystem::path(m.png_dir) / name).string();
    if (!cv::imwrite(path, bgr)) throw RenderError("cannot write image '" + path + "'");
  }
}

size_t FrameWriter::frames_written() const { return impl_->frames; }

}  // namespace probeless::render
