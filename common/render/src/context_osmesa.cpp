#include <GL/osmesa.h>

#include <vector>

#include "context.h"
#include "probeless/render/renderer.h"

namespace probeless::render::internal {

namespace {

class OsMesaContext final : public Context {
 public:
  OsMesaContext(int width, int height) : buffer_(static_cast<size_t>(width) * height * 4) {
    for (const auto& [major, minor] : {std::pair{4, 5}, std::pair{3, 3}}) {
      const int attribs[] = {OSMESA_FORMAT,
                             OSMESA_RGBA,
                             OSMESA_DEPTH_BITS,
                             24,
                             OSMESA_STENCIL_BITS,
                             0,
                             OSMESA_ACCUM_BITS,
                             0,
                             OSMESA_PROFILE,
                             OSMESA_CORE_PROFILE,
                             OSMESA_CONTEXT_MAJOR_VERSION,
                             major,
                             OSMESA_CONTEXT_MINOR_VERSION,
                             minor,
                             0};
      context_ = OSMesaCreateContextAttribs(attribs, nullptr);
      if (context_ != nullptr) break;
    }
    if (context_ == nullptr) {
      throw RenderError("OSMesa: cannot create an OpenGL 4.5 or 3.3 core context");
    }
    if (!OSMesaMakeCurrent(context_, buffer_.data(), GL_UNSIGNED_BYTE, width, height)) {
      OSMesaDestroyContext(context_);
      throw RenderError("OSMesa: cannot make the context current");
    }
  }
  ~OsMesaContext() override { OSMesaDestroyContext(context_); }
  void* GetProc(const char* name) override {
    return reinterpret_cast<void*>(OSMesaGetProcAddress(name));
  }
  bool is_window() const override { return false; }

 private:
  std::vector<unsigned char> buffer_;
  OSMesaContext context_ = nullptr;
};

}  // namespace

std::unique_ptr<Context> CreateOsMesaContext(int width, int height) {
  return std::make_unique<OsMesaContext>(width, height);
}

}  // namespace probeless::render::internal
