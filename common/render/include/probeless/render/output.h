// Writing composites: a PNG sequence and/or a video file (OpenCV VideoWriter), and single PNGs.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "probeless/render/renderer.h"

namespace probeless::render {

// Writes `rgb` (width * height * 3 sRGB bytes, top row first) as a PNG. Throws RenderError if it
// cannot be written.
void WritePng(const std::string& path, int width, int height, std::span<const uint8_t> rgb);
// Reads an 8-bit PNG/JPEG as rgb (width * height * 3). Throws RenderError "cannot read image
// '<path>'" on failure.
std::vector<uint8_t> ReadImageRgb(const std::string& path, int& width, int& height);

class FrameWriter {
 public:
  // `video_path` (empty = none; the container by extension, .avi -> MJPG, .mp4 -> mp4v) at `fps`;
  // `png_dir` (empty = none) receives frame_000001.png, ... (created if missing). Throws
  // RenderError if the directory cannot be created.
  FrameWriter(const std::string& video_path, double fps, const std::string& png_dir);
  ~FrameWriter();
  // Appends one composite. The video is opened at the first frame's size; later frames of another
  // size throw RenderError. Throws RenderError if the video cannot be opened.
  void Write(const Composite& frame);
  size_t frames_written() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace probeless::render
