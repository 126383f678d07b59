// GL contexts of the two back-ends behind one interface (no GL headers here).
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "probeless/render/viewer_click.h"

namespace probeless::render::internal {

class Context {
 public:
  virtual ~Context() = default;
  // The GL function `name` (null if absent).
  virtual void* GetProc(const char* name) = 0;
  virtual bool is_window() const = 0;
  // Window back-end: swap, events, keys, close state and framebuffer size.
  virtual void SwapAndPoll() {}
  virtual std::vector<int> TakeKeys() { return {}; }
  // Window back-end: polls events and returns the left-button presses since the last call, oldest
  // first, in window coordinates (ClickQueue's bound). Contexts without a window report none.
  virtual std::vector<WindowClick> TakeClicks() { return {}; }
  virtual bool Closed() const { return false; }
  virtual std::array<int, 2> FramebufferSize() const { return {0, 0}; }
  // Window back-end: the display server has closed the connection. Thread-safe (reads the
  // connection's socket only).
  virtual bool DisplayLost() const { return false; }
};

// OSMesa context (4.5 core, else 3.3 core) on a width x height RGBA buffer. Throws RenderError.
std::unique_ptr<Context> CreateOsMesaContext(int width, int height);
// GLFW window with a 4.5 core (else 3.3 core) context. Throws RenderError (e.g. no display).
std::unique_ptr<Context> CreateGlfwContext(int width, int height, const std::string& title,
                                           bool visible);

}  // namespace probeless::render::internal
