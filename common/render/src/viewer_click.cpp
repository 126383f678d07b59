#include "probeless/render/viewer_click.h"

#include <algorithm>

namespace probeless::render {

PixelRect LetterboxRect(int image_width, int image_height, int framebuffer_width,
                        int framebuffer_height) {
  if (image_width <= 0 || image_height <= 0 || framebuffer_width <= 0 || framebuffer_height <= 0) {
    return {};
  }
  const double scale = std::min(static_cast<double>(framebuffer_width) / image_width,
                                static_cast<double>(framebuffer_height) / image_height);
  PixelRect r;
  r.w = static_cast<int>(image_width * scale);
  r.h = static_cast<int>(image_height * scale);
  r.x = (framebuffer_width - r.w) / 2;
  // GL's viewport origin is the bottom-left: Present puts the rect's bottom edge at
  // (framebuffer_height - h) / 2 from the bottom, which is this top edge.
  r.y = framebuffer_height - r.h - (framebuffer_height - r.h) / 2;
  return r;
}

std::optional<ViewerClick> WindowToImagePixel(const WindowClick& click, int image_width,
                                              int image_height, std::span<const PixelRect> panels) {
  if (click.window_width <= 0 || click.window_height <= 0) return std::nullopt;
  const PixelRect image =
      LetterboxRect(image_width, image_height, click.framebuffer_width, click.framebuffer_height);
  if (image.w <= 0 || image.h <= 0) return std::nullopt;
  // X11 reports whole window pixels: the click is at the centre of the pixel it names.
  const double fx = (click.x + 0.5) * click.framebuffer_width / click.window_width;
  const double fy = (click.y + 0.5) * click.framebuffer_height / click.window_height;
  if (!image.Contains(fx, fy)) return std::nullopt;
  for (const PixelRect& p : panels) {
    if (p.Contains(fx, fy)) return std::nullopt;
  }
  ViewerClick out;
  out.u = (fx - image.x) * image_width / image.w - 0.5;
  out.v = (fy - image.y) * image_height / image.h - 0.5;
  return out;
}

void ClickQueue::Push(const WindowClick& click) {
  if (clicks_.size() >= kCapacity) {
    clicks_.pop_front();
    ++dropped_;
  }
  clicks_.push_back(click);
}

std::vector<WindowClick> ClickQueue::Take() {
  std::vector<WindowClick> out(clicks_.begin(), clicks_.end());
  clicks_.clear();
  return out;
}

}  // namespace probeless::render
