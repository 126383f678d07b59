// Mouse clicks in the viewer window, from window coordinates to the pixels of the image it shows
// (the renderer's click-to-place, docs/render.md "Placement"). No GL or GLFW here: the window
// back-end (src/context_glfw.cpp) fills a ClickQueue from its events, Renderer::TakeClicks turns
// them into image pixels with WindowToImagePixel and the layout of the last Present.
#pragma once

#include <cstddef>
#include <deque>
#include <optional>
#include <span>
#include <vector>

namespace probeless::render {

// A rectangle of pixels: top-left corner (x, y), top-left origin, and its size.
struct PixelRect {
  int x = 0, y = 0, w = 0, h = 0;
  // True if pixel-space point (px, py) lies in [x, x + w) x [y, y + h).
  bool Contains(double px, double py) const {
    return px >= x && py >= y && px < x + w && py < y + h;
  }
};

// Where Renderer::Present draws an image of image_width x image_height in a framebuffer of
// framebuffer_width x framebuffer_height: the largest rect of the image's aspect ratio (sizes
// truncated to whole pixels), centred (letterbox), in framebuffer pixels with a top-left origin.
// An empty rect (w = h = 0) when either size is not positive.
PixelRect LetterboxRect(int image_width, int image_height, int framebuffer_width,
                        int framebuffer_height);

// A left-button press as the window reports it: the cursor in window coordinates (GLFW screen
// coordinates, top-left origin; they differ from framebuffer pixels on a scaled display) and the
// window's and its framebuffer's sizes at that moment (the user may have resized the window since
// the last frame was shown).
struct WindowClick {
  double x = 0, y = 0;
  int window_width = 0, window_height = 0;
  int framebuffer_width = 0, framebuffer_height = 0;
};

// A click on the image the viewer shows, in that image's pixels (render::Intrinsics convention:
// (0, 0) is the centre of the top-left pixel, so the click fell in pixel (floor(u + 0.5),
// floor(v + 0.5))).
struct ViewerClick {
  double u = 0, v = 0;
};

// The image pixel under `click` when the window shows an image of image_width x image_height
// letterboxed (LetterboxRect) with `panels` (framebuffer pixels, top-left origin, as
// render::Panel's x, y, w, h) drawn over it. The cursor position is taken as the centre of the
// window pixel it names, scaled to framebuffer pixels by framebuffer size / window size. nullopt on
// the black bars, on a panel, or when a size is not positive (a minimised window, no image shown
// yet); otherwise -0.5 <= u < image_width - 0.5 and -0.5 <= v < image_height - 0.5.
std::optional<ViewerClick> WindowToImagePixel(const WindowClick& click, int image_width,
                                              int image_height,
                                              std::span<const PixelRect> panels = {});

// The clicks of one window between two polls, oldest first. Bounded: a click beyond kCapacity
// unpolled ones drops the oldest (counted in dropped()), so a window nobody polls does not grow.
// Not thread-safe: GLFW delivers events on the thread that polls them, which is the renderer's.
class ClickQueue {
 public:
  static constexpr size_t kCapacity = 16;
  void Push(const WindowClick& click);
  // The queued clicks, oldest first; the queue is empty afterwards.
  std::vector<WindowClick> Take();
  size_t size() const { return clicks_.size(); }
  // Clicks dropped because the queue was full, since construction.
  size_t dropped() const { return dropped_; }

 private:
  std::deque<WindowClick> clicks_;
  size_t dropped_ = 0;
};

}  // namespace probeless::render
