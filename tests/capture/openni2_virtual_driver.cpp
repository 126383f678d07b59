// A small OpenNI2 driver plugin (libProbelessVirtual.so) serving a virtual RGB-D device, so the
// capture_openni2 node is tested through the real OpenNI2 library: OpenNI2 loads it from the
// "OpenNI2/Drivers" folder next to the libOpenNI2.so.0 it was loaded from (Debian reads its
// OpenNI.ini from /etc/openni2, so the test places a copy of the library in a private folder).
//
// Device URI "probeless://virtual": depth 640x480 @ 30 Hz in 1 mm units and colour RGB888
// 640x480 @ 30 Hz. Frame n: depth(x, y) = 800 + 2 x + y + n (mm; 0 in the 8x8 top-left corner),
// colour(x, y) = (x & 255, y & 255, n & 255). Fields of view 58 x 45 degrees.
// Env: PROBELESS_VIRTUAL_NO_REGISTRATION=1 hides hardware registration (software path);
// PROBELESS_VIRTUAL_FRAMES=N stops delivering after N frames per stream (a stalled device);
// PROBELESS_VIRTUAL_STRAY_THREAD=1 starts a thread that shutdown() leaves running in this
// library, as Debian's PS1080/PSLink drivers do when their udev thread is late (unloading the
// driver under it then crashes the process).
#include <Driver/OniDriverAPI.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <thread>

// OniDriverAPI.h's ONI_EXPORT_DRIVER uses XnOS.h macros that Debian does not package.
#define XN_NEW(type, arg) new type(arg)
#define XN_DELETE(p) delete (p)

namespace {

constexpr int kWidth = 640;
constexpr int kHeight = 480;
constexpr const char* kUri = "probeless://virtual";

class VirtualStream : public oni::driver::StreamBase {
 public:
  explicit VirtualStream(OniSensorType type) : type_(type) {
    mode_.pixelFormat =
        type == ONI_SENSOR_DEPTH ? ONI_PIXEL_FORMAT_DEPTH_1_MM : ONI_PIXEL_FORMAT_RGB888;
    mode_.resolutionX = kWidth;
    mode_.resolutionY = kHeight;
    mode_.fps = 30;
    if (const char* n = std::getenv("PROBELESS_VIRTUAL_FRAMES")) limit_ = std::atoi(n);
  }
  ~VirtualStream() override { stop(); }

  OniStatus start() override {
    running_ = true;
    thread_ = std::thread([this] { Run(); });
    return ONI_STATUS_OK;
  }
  void stop() override {
    running_ = false;
    if (thread_.joinable()) thread_.join();
  }
  int getRequiredFrameSize() override {
    return kWidth * kHeight * (type_ == ONI_SENSOR_DEPTH ? 2 : 3);
  }
  OniBool isPropertySupported(int id) override {
    return id == ONI_STREAM_PROPERTY_VIDEO_MODE || id == ONI_STREAM_PROPERTY_HORIZONTAL_FOV ||
           id == ONI_STREAM_PROPERTY_VERTICAL_FOV || id == ONI_STREAM_PROPERTY_MIRRORING ||
           id == ONI_STREAM_PROPERTY_MAX_VALUE || id == ONI_STREAM_PROPERTY_MIN_VALUE;
  }
  OniStatus getProperty(int id, void* data, int* size) override {
    switch (id) {
      case ONI_STREAM_PROPERTY_VIDEO_MODE:
        *static_cast<OniVideoMode*>(data) = mode_;
        *size = sizeof(OniVideoMode);
        return ONI_STATUS_OK;
      case ONI_STREAM_PROPERTY_HORIZONTAL_FOV:
        *static_cast<float*>(data) = static_cast<float>(58.0 * M_PI / 180);
        *size = sizeof(float);
        return ONI_STATUS_OK;
      case ONI_STREAM_PROPERTY_VERTICAL_FOV:
        *static_cast<float*>(data) = static_cast<float>(45.0 * M_PI / 180);
        *size = sizeof(float);
        return ONI_STATUS_OK;
      case ONI_STREAM_PROPERTY_MIRRORING:
        *static_cast<OniBool*>(data) = mirroring_;
        *size = sizeof(OniBool);
        return ONI_STATUS_OK;
      case ONI_STREAM_PROPERTY_MAX_VALUE:
        *static_cast<int*>(data) = 10000;
        *size = sizeof(int);
        return ONI_STATUS_OK;
      case ONI_STREAM_PROPERTY_MIN_VALUE:
        *static_cast<int*>(data) = 0;
        *size = sizeof(int);
        return ONI_STATUS_OK;
    }
    return ONI_STATUS_NOT_SUPPORTED;
  }
  OniStatus setProperty(int id, const void* data, int size) override {
    if (id == ONI_STREAM_PROPERTY_VIDEO_MODE && size == sizeof(OniVideoMode)) {
      const OniVideoMode& m = *static_cast<const OniVideoMode*>(data);
      if (m.resolutionX != kWidth || m.resolutionY != kHeight ||
          m.pixelFormat != mode_.pixelFormat) {
        return ONI_STATUS_NOT_SUPPORTED;
      }
      mode_ = m;
      return ONI_STATUS_OK;
    }
    if (id == ONI_STREAM_PROPERTY_MIRRORING && size == sizeof(OniBool)) {
      mirroring_ = *static_cast<const OniBool*>(data);
      return ONI_STATUS_OK;
    }
    return ONI_STATUS_NOT_SUPPORTED;
  }

 private:
  void Run() {
    const auto start = std::chrono::steady_clock::now();
    for (int n = 0; running_; ++n) {
      std::this_thread::sleep_until(start + std::chrono::microseconds(33333) * n);
      if (!running_) break;
      if (limit_ > 0 && n >= limit_) continue;  // stalled: keeps "streaming" without frames
      OniFrame* frame = getServices().acquireFrame();
      if (frame == nullptr) continue;
      frame->frameIndex = n + 1;
      frame->timestamp = static_cast<uint64_t>(n) * 33333;
      frame->videoMode = mode_;
      frame->width = kWidth;
      frame->height = kHeight;
      frame->croppingEnabled = FALSE;
      frame->cropOriginX = frame->cropOriginY = 0;
      frame->sensorType = type_;
      if (type_ == ONI_SENSOR_DEPTH) {
        frame->stride = kWidth * 2;
        frame->dataSize = kWidth * kHeight * 2;
        auto* d = static_cast<uint16_t*>(frame->data);
        for (int y = 0; y < kHeight; ++y) {
          for (int x = 0; x < kWidth; ++x) {
            d[y * kWidth + x] = (x < 8 && y < 8) ? 0 : static_cast<uint16_t>(800 + 2 * x + y + n);
          }
        }
      } else {
        frame->stride = kWidth * 3;
        frame->dataSize = kWidth * kHeight * 3;
        auto* c = static_cast<uint8_t*>(frame->data);
        for (int y = 0; y < kHeight; ++y) {
          for (int x = 0; x < kWidth; ++x) {
            uint8_t* p = c + (y * kWidth + x) * 3;
            p[0] = static_cast<uint8_t>(x & 255);
            p[1] = static_cast<uint8_t>(y & 255);
            p[2] = static_cast<uint8_t>(n & 255);
          }
        }
      }
      raiseNewFrame(frame);
      getServices().releaseFrame(frame);
    }
  }

  OniSensorType type_;
  OniVideoMode mode_{};
  OniBool mirroring_ = FALSE;
  int limit_ = 0;
  std::atomic<bool> running_{false};
  std::thread thread_;
};

class VirtualDevice : public oni::driver::DeviceBase {
 public:
  VirtualDevice() {
    depth_mode_ = {ONI_PIXEL_FORMAT_DEPTH_1_MM, kWidth, kHeight, 30};
    colour_mode_ = {ONI_PIXEL_FORMAT_RGB888, kWidth, kHeight, 30};
    sensors_[0] = {ONI_SENSOR_DEPTH, 1, &depth_mode_};
    sensors_[1] = {ONI_SENSOR_COLOR, 1, &colour_mode_};
    hardware_registration_ = std::getenv("PROBELESS_VIRTUAL_NO_REGISTRATION") == nullptr;
  }
  OniStatus getSensorInfoList(OniSensorInfo** infos, int* count) override {
    *infos = sensors_;
    *count = 2;
    return ONI_STATUS_OK;
  }
  oni::driver::StreamBase* createStream(OniSensorType type) override {
    if (type != ONI_SENSOR_DEPTH && type != ONI_SENSOR_COLOR) return nullptr;
    return new VirtualStream(type);
  }
  void destroyStream(oni::driver::StreamBase* stream) override { delete stream; }
  OniBool isImageRegistrationModeSupported(OniImageRegistrationMode mode) override {
    return mode == ONI_IMAGE_REGISTRATION_OFF ||
           (hardware_registration_ && mode == ONI_IMAGE_REGISTRATION_DEPTH_TO_COLOR);
  }
  OniBool isPropertySupported(int id) override {
    return id == ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION;
  }
  OniStatus setProperty(int id, const void* data, int size) override {
    if (id == ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION && size == sizeof(OniImageRegistrationMode)) {
      const auto mode = *static_cast<const OniImageRegistrationMode*>(data);
      if (!isImageRegistrationModeSupported(mode)) return ONI_STATUS_NOT_SUPPORTED;
      registration_ = mode;
      return ONI_STATUS_OK;
    }
    return ONI_STATUS_NOT_SUPPORTED;
  }
  OniStatus getProperty(int id, void* data, int* size) override {
    if (id == ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION) {
      *static_cast<OniImageRegistrationMode*>(data) = registration_;
      *size = sizeof(OniImageRegistrationMode);
      return ONI_STATUS_OK;
    }
    return ONI_STATUS_NOT_SUPPORTED;
  }

 private:
  OniVideoMode depth_mode_{};
  OniVideoMode colour_mode_{};
  OniSensorInfo sensors_[2]{};
  bool hardware_registration_ = true;
  OniImageRegistrationMode registration_ = ONI_IMAGE_REGISTRATION_OFF;
};

class VirtualDriver : public oni::driver::DriverBase {
 public:
  explicit VirtualDriver(OniDriverServices* services) : DriverBase(services) {}
  OniStatus initialize(oni::driver::DeviceConnectedCallback connected,
                       oni::driver::DeviceDisconnectedCallback disconnected,
                       oni::driver::DeviceStateChangedCallback state_changed,
                       void* cookie) override {
    DriverBase::initialize(connected, disconnected, state_changed, cookie);
    std::memset(&info_, 0, sizeof(info_));
    std::strncpy(info_.uri, kUri, sizeof(info_.uri) - 1);
    std::strncpy(info_.vendor, "probeless", sizeof(info_.vendor) - 1);
    std::strncpy(info_.name, "Virtual RGB-D", sizeof(info_.name) - 1);
    deviceConnected(&info_);
    if (std::getenv("PROBELESS_VIRTUAL_STRAY_THREAD") != nullptr) {
      static std::atomic<uint64_t> spins{0};
      std::thread([] {
        for (;;) spins.fetch_add(1, std::memory_order_relaxed);  // runs this library's code
      }).detach();
      while (spins.load() == 0) std::this_thread::yield();  // it is running before we return
    }
    return ONI_STATUS_OK;
  }
  oni::driver::DeviceBase* deviceOpen(const char* uri, const char*) override {
    if (std::strcmp(uri, kUri) != 0) return nullptr;
    return new VirtualDevice();
  }
  void deviceClose(oni::driver::DeviceBase* device) override { delete device; }
  OniStatus tryDevice(const char* uri) override {
    return std::strcmp(uri, kUri) == 0 ? ONI_STATUS_OK : ONI_STATUS_ERROR;
  }
  void shutdown() override {}

 private:
  OniDeviceInfo info_{};
};

}  // namespace

ONI_EXPORT_DRIVER(VirtualDriver)
