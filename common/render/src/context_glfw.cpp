#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <X11/Xlib.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdio>
#include <mutex>
#include <string>

#include "context.h"
#include "probeless/render/renderer.h"

// GLFW's X11 native accessor (glfw3native.h would need the Xrandr headers for just this).
extern "C" Display* glfwGetX11Display(void);

namespace probeless::render::internal {

namespace {

std::string& LastGlfwError() {
  static std::string error;
  return error;
}

void OnError(int code, const char* description) {
  LastGlfwError() = description != nullptr ? description : ("error " + std::to_string(code));
}

// Xlib's default handler of a dead connection calls exit(), which can hang in atexit handlers while
// GL worker threads run: one clear line and _exit instead.
int OnDisplayLost(Display*) {
  static const char kMessage[] =
      "[error] render: the X display closed the connection (window backend); run with "
      "backend:=offscreen or under xvfb-run -a\n";
  (void)!::write(STDERR_FILENO, kMessage, sizeof(kMessage) - 1);
  ::_exit(1);
}

class GlfwContext final : public Context {
 public:
  GlfwContext(int width, int height, const std::string& title, bool visible) {
    glfwSetErrorCallback(OnError);
    if (!glfwInit()) {
      throw RenderError("GLFW: cannot initialise (" + LastGlfwError() +
                        "); is a display available (try xvfb-run -a)?");
    }
    for (const auto& [major, minor] : {std::pair{4, 5}, std::pair{3, 3}}) {
      glfwDefaultWindowHints();
      glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, major);
      glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, minor);
      glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
      glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
      glfwWindowHint(GLFW_VISIBLE, visible ? GLFW_TRUE : GLFW_FALSE);
      glfwWindowHint(GLFW_RESIZABLE, GLFW_TRUE);
      window_ = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
      if (window_ != nullptr) break;
    }
    if (window_ == nullptr) {
      const std::string error = LastGlfwError();
      glfwTerminate();
      throw RenderError("GLFW: cannot create a window with an OpenGL 4.5 or 3.3 core context (" +
                        error + ")");
    }
    // GLFW 3.3 on Debian runs on X11 only.
    if (Display* display = glfwGetX11Display()) {
      XSetIOErrorHandler(OnDisplayLost);
      display_fd_ = ConnectionNumber(display);
    }
    glfwMakeContextCurrent(window_);
    glfwSwapInterval(0);
    glfwSetWindowUserPointer(window_, this);
    glfwSetKeyCallback(window_, [](GLFWwindow* w, int key, int, int action, int) {
      if (action != GLFW_PRESS) return;
      auto* self = static_cast<GlfwContext*>(glfwGetWindowUserPointer(w));
      self->keys_.push_back(key);
      if (key == GLFW_KEY_ESCAPE) glfwSetWindowShouldClose(w, GLFW_TRUE);
    });
    // The press's position is the last one the event stream reported (motion and enter events
    // precede the press in order), not the pointer's position when the events are polled, which
    // can be a frame later.
    glfwSetCursorPosCallback(window_, [](GLFWwindow* w, double x, double y) {
      auto* self = static_cast<GlfwContext*>(glfwGetWindowUserPointer(w));
      self->cursor_ = {x, y};
      self->cursor_known_ = true;
    });
    glfwSetMouseButtonCallback(window_, [](GLFWwindow* w, int button, int action, int) {
      if (button != GLFW_MOUSE_BUTTON_LEFT || action != GLFW_PRESS) return;
      auto* self = static_cast<GlfwContext*>(glfwGetWindowUserPointer(w));
      WindowClick click;
      if (self->cursor_known_) {
        click.x = self->cursor_[0];
        click.y = self->cursor_[1];
      } else {
        glfwGetCursorPos(w, &click.x, &click.y);
      }
      glfwGetWindowSize(w, &click.window_width, &click.window_height);
      glfwGetFramebufferSize(w, &click.framebuffer_width, &click.framebuffer_height);
      self->clicks_.Push(click);
    });
  }
  ~GlfwContext() override {
    if (DisplayLost()) return;  // nothing to tear down on a dead connection (Xlib would exit)
    glfwDestroyWindow(window_);
    glfwTerminate();
  }
  void* GetProc(const char* name) override {
    return reinterpret_cast<void*>(glfwGetProcAddress(name));
  }
  bool is_window() const override { return true; }
  void SwapAndPoll() override {
    glfwSwapBuffers(window_);
    glfwPollEvents();
  }
  std::vector<int> TakeKeys() override {
    glfwPollEvents();
    std::vector<int> keys;
    keys.swap(keys_);
    return keys;
  }
  std::vector<WindowClick> TakeClicks() override {
    glfwPollEvents();
    return clicks_.Take();
  }
  bool Closed() const override { return glfwWindowShouldClose(window_); }
  bool DisplayLost() const override {
    if (display_fd_ < 0) return false;
    pollfd p{display_fd_, POLLIN, 0};
    if (::poll(&p, 1, 0) <= 0) return false;
    if (p.revents & (POLLHUP | POLLERR | POLLNVAL)) return true;
    // Readable: events, or end of stream when the server has gone (peek, so Xlib still reads them).
    char byte;
    return ::recv(display_fd_, &byte, 1, MSG_PEEK | MSG_DONTWAIT) == 0;
  }
  std::array<int, 2> FramebufferSize() const override {
    int w = 0, h = 0;
    glfwGetFramebufferSize(window_, &w, &h);
    return {w, h};
  }

 private:
  GLFWwindow* window_ = nullptr;
  std::vector<int> keys_;
  ClickQueue clicks_;
  std::array<double, 2> cursor_{0, 0};  // window coordinates
  bool cursor_known_ = false;
  int display_fd_ = -1;  // the X connection's socket (X11 platform only)
};

}  // namespace

std::unique_ptr<Context> CreateGlfwContext(int width, int height, const std::string& title,
                                           bool visible) {
  return std::make_unique<GlfwContext>(width, height, title, visible);
}

}  // namespace probeless::render::internal
