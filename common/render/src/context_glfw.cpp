#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include <mutex>
#include <string>

#include "context.h"
#include "probeless/render/renderer.h"

namespace probeless::render::internal {

namespace {

std::string& LastGlfwError() {
  static std::string error;
  return error;
}

void OnError(int code, const char* description) {
  LastGlfwError() = description != nullptr ? description : ("error " + std::to_string(code));
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
    glfwMakeContextCurrent(window_);
    glfwSwapInterval(0);
    glfwSetWindowUserPointer(window_, this);
    glfwSetKeyCallback(window_, [](GLFWwindow* w, int key, int, int action, int) {
      if (action != GLFW_PRESS) return;
      auto* self = static_cast<GlfwContext*>(glfwGetWindowUserPointer(w));
      self->keys_.push_back(key);
      if (key == GLFW_KEY_ESCAPE) glfwSetWindowShouldClose(w, GLFW_TRUE);
    });
  }
  ~GlfwContext() override {
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
  bool Closed() const override { return glfwWindowShouldClose(window_); }
  std::array<int, 2> FramebufferSize() const override {
    int w = 0, h = 0;
    glfwGetFramebufferSize(window_, &w, &h);
    return {w, h};
  }

 private:
  GLFWwindow* window_ = nullptr;
  std::vector<int> keys_;
};

}  // namespace

std::unique_ptr<Context> CreateGlfwContext(int width, int height, const std::string& title,
                                           bool visible) {
  return std::make_unique<GlfwContext>(width, height, title, visible);
}

}  // namespace probeless::render::internal
