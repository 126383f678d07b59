// OpenNI2 backend (PrimeSense-family devices and .oni recordings). OpenNI.h stays in this file.
#include <OpenNI.h>

#include <cmath>
#include <filesystem>
#include <vector>

#include "probeless/capture/capture_error.h"
#include "probeless/capture/device.h"

namespace probeless::capture {

namespace {

std::string LastError() {
  std::string e = openni::OpenNI::getExtendedError();
  while (!e.empty() && (e.back() == '\n' || e.back() == ' ')) e.pop_back();
  for (char& c : e) {
    if (c == '\n') c = ' ';
  }
  return e.empty() ? "no detail" : e;
}

// OpenNI2 is initialised once per process and never shut down. Shutting it down unloads the USB
// drivers (PS1080, PSLink), which first wait 2 s for their udev thread and then cancel it and
// dlclose the library it runs in: on a loaded machine that thread is late and the process dies
// with SIGSEGV after its error was reported. Those threads also deliver hot-plug events, so a
// retry sees a newly plugged device without re-initialising. A failed initialisation is retried
// by the next call (the static stays uninitialised when the lambda throws).
void EnsureOpenNiInitialised() {
  static const bool initialised = [] {
    if (openni::OpenNI::initialize() != openni::STATUS_OK) {
      throw CaptureError(ErrorKind::kDeviceError,
                         "OpenNI2 does not initialise: " + LastError() +
                             " (drivers in /usr/lib/x86_64-linux-gnu/OpenNI2/Drivers, "
                             "/etc/openni2/OpenNI.ini)");
    }
    return true;
  }();
  (void)initialised;
}

// Constructed first in the device so that OpenNI2 is up before any openni:: member is made.
struct OpenNiRuntime {
  OpenNiRuntime() { EnsureOpenNiInitialised(); }
};

class OpenNi2Device final : public Device {
 public:
  OpenNi2Device(const OpenNi2Options& options, const std::function<void(const std::string&)>& log)
      : options_(options) {
    const bool is_file = options.uri.ends_with(".oni") || options.uri.ends_with(".ONI");
    description_ = is_file               ? "OpenNI2 recording '" + options.uri + "'"
                   : options.uri.empty() ? std::string("OpenNI2 device (first found)")
                                         : "OpenNI2 device '" + options.uri + "'";
    if (is_file && !std::filesystem::is_regular_file(options.uri)) {
      throw CaptureError(ErrorKind::kBadInput,
                         description_ + " does not exist: give the path of an .oni file");
    }
    if (!is_file) {
      openni::Array<openni::DeviceInfo> list;
      openni::OpenNI::enumerateDevices(&list);
      bool found = false;
      std::string uris;
      for (int i = 0; i < list.getSize(); ++i) {
        uris += std::string(uris.empty() ? "" : ", ") + list[i].getUri();
        if (options.uri.empty() || options.uri == list[i].getUri()) found = true;
      }
      if (!found) {
        throw CaptureError(
            ErrorKind::kNoDevice,
            description_ + " is not connected (" +
                (uris.empty() ? std::string("OpenNI2 finds no device") : "found: " + uris) +
                "): plug it in, check lsusb and the udev rules in docs/capture.md");
      }
    }
    if (device_.open(options.uri.empty() ? openni::ANY_DEVICE : options.uri.c_str()) !=
        openni::STATUS_OK) {
      throw CaptureError(is_file ? ErrorKind::kBadInput : ErrorKind::kBusy,
                         description_ + " cannot be opened: " + LastError() +
                             (is_file ? std::string(" (not an .oni recording?)")
                                      : std::string(" (in use by another process, or no "
                                                    "permission on its USB device)")));
    }
    description_ += std::string(" (") + device_.getDeviceInfo().getVendor() + " " +
                    device_.getDeviceInfo().getName() + ")";
    if (is_file && device_.getPlaybackControl() != nullptr) {
      device_.getPlaybackControl()->setRepeatEnabled(options.loop_recording);
      device_.getPlaybackControl()->setSpeed(1.0f);
      playback_ = true;
    }
    if (options.depth && device_.hasSensor(openni::SENSOR_DEPTH)) {
      CreateStream(depth_stream_, openni::SENSOR_DEPTH, openni::PIXEL_FORMAT_DEPTH_1_MM);
    }
    if (options.colour && device_.hasSensor(openni::SENSOR_COLOR)) {
      CreateStream(colour_stream_, openni::SENSOR_COLOR, openni::PIXEL_FORMAT_RGB888);
    }
    if (!depth_stream_.isValid() && !colour_stream_.isValid()) {
      throw CaptureError(ErrorKind::kBadInput, description_ + " has none of the requested streams");
    }
    // Registration.
    if (depth_stream_.isValid() && colour_stream_.isValid() && options.registration != "off") {
      const bool hardware =
          device_.isImageRegistrationModeSupported(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR);
      if (options.registration == "hardware" && !hardware) {
        throw CaptureError(ErrorKind::kBadInput,
                           description_ +
                               " has no hardware depth-to-colour registration: set param "
                               "registration to auto or software");
      }
      if (hardware && options.registration != "software" &&
          device_.setImageRegistrationMode(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR) ==
              openni::STATUS_OK) {
        registered_ = true;
        log(description_ + ": hardware depth-to-colour registration on");
      } else {
        software_registration_ = true;
        registered_ = true;
        log(description_ +
            ": software depth-to-colour registration (factory fields of view, "
            "depth-to-colour translation [" +
            std::to_string(options.depth_to_colour.translation_m[0]) + ", " +
            std::to_string(options.depth_to_colour.translation_m[1]) + ", " +
            std::to_string(options.depth_to_colour.translation_m[2]) + "] m)");
      }
      if (device_.setDepthColorSyncEnabled(true) != openni::STATUS_OK) {
        log(description_ + ": no depth/colour frame sync: " + LastError());
      }
    }
    if (depth_stream_.isValid()) depth_stream_.setMirroringEnabled(false);
    if (colour_stream_.isValid()) colour_stream_.setMirroringEnabled(false);
    for (openni::VideoStream* s : {&depth_stream_, &colour_stream_}) {
      if (!s->isValid()) continue;
      if (s->start() != openni::STATUS_OK) {
        throw CaptureError(ErrorKind::kDeviceError,
                           description_ + " does not start streaming: " + LastError());
      }
      streams_.push_back(s);
    }
    if (colour_stream_.isValid()) {
      const openni::VideoMode mode = colour_stream_.getVideoMode();
      colour_ = StreamInfo{PixelFormat::kRgb24, static_cast<uint32_t>(mode.getResolutionX()),
                           static_cast<uint32_t>(mode.getResolutionY()),
                           static_cast<double>(mode.getFps())};
      colour_k_ = FieldOfViewIntrinsics(colour_stream_, colour_->width, colour_->height);
    }
    if (depth_stream_.isValid()) {
      const openni::VideoMode mode = depth_stream_.getVideoMode();
      depth_k_ = FieldOfViewIntrinsics(depth_stream_, mode.getResolutionX(), mode.getResolutionY());
      depth_ = StreamInfo{PixelFormat::kDepthMm, depth_k_.width, depth_k_.height,
                          static_cast<double>(mode.getFps())};
      if (software_registration_) {
        depth_->width = colour_->width;
        depth_->height = colour_->height;
        registered_depth_.assign(static_cast<size_t>(colour_->width) * colour_->height, 0);
      }
    }
  }

  ~OpenNi2Device() override {
    depth_ref_.release();
    colour_ref_.release();
    for (openni::VideoStream* s : streams_) s->stop();
    depth_stream_.destroy();
    colour_stream_.destroy();
    device_.close();
  }

  const std::string& description() const override { return description_; }
  std::optional<StreamInfo> colour_stream() const override { return colour_; }
  std::optional<StreamInfo> depth_stream() const override { return depth_; }
  bool depth_registered() const override { return registered_; }
  std::optional<Intrinsics> factory_intrinsics() const override {
    return colour_ ? colour_k_ : depth_k_;
  }

  bool Next(std::chrono::milliseconds timeout, FrameSet& frames) override {
    int index = -1;
    const openni::Status status =
        openni::OpenNI::waitForAnyStream(streams_.data(), static_cast<int>(streams_.size()), &index,
                                         static_cast<int>(timeout.count()));
    if (status == openni::STATUS_TIME_OUT) {
      if (playback_ && !options_.loop_recording && delivered_ > 0 &&
          std::chrono::steady_clock::now() - last_frame_ > std::chrono::milliseconds(500)) {
        throw CaptureError(ErrorKind::kBadInput,
                           description_ + " ended (set param loop: true to replay it)");
      }
      return false;
    }
    if (status != openni::STATUS_OK || index < 0) {
      throw CaptureError(ErrorKind::kDisconnected,
                         description_ + " stopped delivering: " + LastError() + ": replug it");
    }
    openni::VideoStream& stream = *streams_[index];
    openni::VideoFrameRef& ref = (&stream == &depth_stream_) ? depth_ref_ : colour_ref_;
    if (stream.readFrame(&ref) != openni::STATUS_OK || !ref.isValid()) {
      throw CaptureError(ErrorKind::kDisconnected,
                         description_ + " frame read failed: " + LastError() + ": replug it");
    }
    const int64_t arrival = MonotonicNowNs();
    ++delivered_;
    last_frame_ = std::chrono::steady_clock::now();
    RawFrame f;
    f.width = static_cast<uint32_t>(ref.getWidth());
    f.height = static_cast<uint32_t>(ref.getHeight());
    f.stride = static_cast<uint32_t>(ref.getStrideInBytes());
    f.data = {static_cast<const uint8_t*>(ref.getData()), static_cast<size_t>(ref.getDataSize())};
    f.sequence = static_cast<uint64_t>(ref.getFrameIndex());
    // OpenNI2 stamps frames in microseconds of the device clock (start of frame).
    f.stamp_mono_ns = clock_.ToMonotonic(static_cast<int64_t>(ref.getTimestamp()) * 1000, arrival);
    if (&stream == &depth_stream_) {
      f.format = PixelFormat::kDepthMm;
      if (software_registration_) {
        RegisterDepthToColour(reinterpret_cast<const uint16_t*>(f.data.data()), f.stride,
                              calib::ScaleIntrinsics(depth_k_, f.width, f.height), colour_k_,
                              options_.depth_to_colour, registered_depth_.data(),
                              colour_->width * 2);
        f.width = colour_->width;
        f.height = colour_->height;
        f.stride = colour_->width * 2;
        f.data = {reinterpret_cast<const uint8_t*>(registered_depth_.data()),
                  registered_depth_.size() * 2};
      }
      frames.depth = f;
    } else {
      f.format = PixelFormat::kRgb24;
      frames.colour = f;
    }
    return true;
  }

 private:
  void CreateStream(openni::VideoStream& stream, openni::SensorType type,
                    openni::PixelFormat format) {
    const char* name = type == openni::SENSOR_DEPTH ? "depth" : "colour";
    if (stream.create(device_, type) != openni::STATUS_OK) {
      throw CaptureError(ErrorKind::kDeviceError,
                         description_ + " cannot create its " + name + " stream: " + LastError());
    }
    if (playback_) return;  // a recording keeps its own modes
    const openni::SensorInfo& info = stream.getSensorInfo();
    const openni::Array<openni::VideoMode>& modes = info.getSupportedVideoModes();
    int best = -1;
    double best_score = 1e18;
    std::string offered;
    for (int i = 0; i < modes.getSize(); ++i) {
      const openni::VideoMode& m = modes[i];
      offered += std::string(offered.empty() ? "" : ", ") + std::to_string(m.getResolutionX()) +
                 "x" + std::to_string(m.getResolutionY()) + "@" + std::to_string(m.getFps()) +
                 " format " + std::to_string(static_cast<int>(m.getPixelFormat()));
      if (m.getPixelFormat() != format) continue;
      const double score = std::abs(m.getResolutionX() - static_cast<double>(options_.width)) +
                           std::abs(m.getResolutionY() - static_cast<double>(options_.height)) +
                           10 * std::abs(m.getFps() - options_.fps);
      if (score < best_score) {
        best_score = score;
        best = i;
      }
    }
    if (best < 0) {
      throw CaptureError(ErrorKind::kBadInput,
                         description_ + " offers no " + name + " stream in " +
                             (type == openni::SENSOR_DEPTH ? "1 mm depth" : "RGB888") +
                             " (modes: " + offered + ")");
    }
    if (stream.setVideoMode(modes[best]) != openni::STATUS_OK) {
      throw CaptureError(ErrorKind::kDeviceError,
                         description_ + " rejects its " + name + " mode: " + LastError());
    }
  }

  static Intrinsics FieldOfViewIntrinsics(openni::VideoStream& stream, uint32_t width,
                                          uint32_t height) {
    const double hfov = stream.getHorizontalFieldOfView();
    const double vfov = stream.getVerticalFieldOfView();
    Intrinsics k = calib::IntrinsicsFromFieldOfView(
        width, height, hfov > 0.1 && hfov < 3.0 ? hfov * 180 / M_PI : 58.0);
    if (vfov > 0.1 && vfov < 3.0) k.fy = height / (2 * std::tan(vfov / 2));
    return k;
  }

  OpenNiRuntime runtime_;  // first member: OpenNI2 is initialised before the other members
  OpenNi2Options options_;
  std::string description_;
  openni::Device device_;
  openni::VideoStream depth_stream_;
  openni::VideoStream colour_stream_;
  std::vector<openni::VideoStream*> streams_;
  openni::VideoFrameRef depth_ref_;
  openni::VideoFrameRef colour_ref_;
  std::optional<StreamInfo> colour_;
  std::optional<StreamInfo> depth_;
  Intrinsics colour_k_;
  Intrinsics depth_k_;
  bool registered_ = false;
  bool software_registration_ = false;
  bool playback_ = false;
  std::vector<uint16_t> registered_depth_;
  DeviceClock clock_;
  uint64_t delivered_ = 0;
  std::chrono::steady_clock::time_point last_frame_;
};

}  // namespace

std::unique_ptr<Device> OpenOpenNi2(const OpenNi2Options& options,
                                    const std::function<void(const std::string&)>& log) {
  return std::make_unique<OpenNi2Device>(options, log);
}

}  // namespace probeless::capture
