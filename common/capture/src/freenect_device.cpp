// libfreenect backend (Kinect v1). libfreenect.h stays in this file.
#include <libfreenect.h>
#include <sys/time.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <vector>

#include "probeless/capture/capture_error.h"
#include "probeless/capture/device.h"
#include "probeless/parse/number.h"

namespace probeless::capture {

namespace {

constexpr int64_t kHalfFrameNs = 16'666'667;  // stamps: arrival minus half a 30 Hz frame

class FreenectDevice final : public Device {
 public:
  FreenectDevice(const FreenectOptions& options,
                 const std::function<void(const std::string&)>& log) {
    // An all-digit device is an index; checked before libfreenect starts, so a 20-digit index is
    // bad input (never retried), not an uncaught std::out_of_range from stoi.
    const bool digits_only = options.device.empty() ||
                             options.device.find_first_not_of("0123456789") == std::string::npos;
    const std::optional<int> index = options.device.empty()
                                         ? std::optional<int>(0)
                                         : parse::TryParseInteger<int>(options.device, 0);
    if (digits_only && !index) {
      throw CaptureError(ErrorKind::kBadInput,
                         "param device expects a Kinect index (a non-negative integer up to " +
                             std::to_string(std::numeric_limits<int>::max()) +
                             ") or a serial, got '" + options.device + "'");
    }
    if (freenect_init(&context_, nullptr) < 0 || context_ == nullptr) {
      throw CaptureError(ErrorKind::kDeviceError,
                         "libfreenect could not initialise libusb: check that /dev/bus/usb is "
                         "accessible (in a container: pass the USB bus through)");
    }
    freenect_set_log_level(context_, FREENECT_LOG_FATAL);
    freenect_select_subdevices(
        context_,
        static_cast<freenect_device_flags>(
            FREENECT_DEVICE_CAMERA |
            ((std::isnan(options.tilt_deg) && options.led < 0) ? 0 : FREENECT_DEVICE_MOTOR)));
    const int count = freenect_num_devices(context_);
    const bool by_index = digits_only;
    description_ = by_index ? "Kinect v1 #" + (options.device.empty() ? "0" : options.device)
                            : "Kinect v1 with serial '" + options.device + "'";
    if (count <= 0) {
      Close();
      throw CaptureError(ErrorKind::kNoDevice,
                         description_ +
                             ": libfreenect finds no Kinect v1: plug it in (USB and its power "
                             "adapter), check `lsusb -d 045e:02ae`, see docs/capture.md for udev");
    }
    int rc = 0;
    if (by_index) {
      if (*index >= count) {
        Close();
        throw CaptureError(ErrorKind::kNoDevice,
                           description_ + " does not exist: libfreenect sees " +
                               std::to_string(count) + " Kinect(s); pick param device 0.." +
                               std::to_string(count - 1));
      }
      rc = freenect_open_device(context_, &device_, *index);
    } else {
      rc = freenect_open_device_by_camera_serial(context_, &device_, options.device.c_str());
    }
    if (rc < 0 || device_ == nullptr) {
      device_ = nullptr;
      Close();
      throw CaptureError(ErrorKind::kBusy,
                         description_ +
                             " cannot be opened: another process uses it, or no permission on its "
                             "USB device (udev rule in docs/capture.md)");
    }
    freenect_set_user(device_, this);
    if (!std::isnan(options.tilt_deg)) {
      freenect_set_tilt_degs(device_, std::clamp(options.tilt_deg, -30.0, 30.0));
    }
    if (options.led >= 0) freenect_set_led(device_, static_cast<freenect_led_options>(options.led));

    if (options.colour) {
      const freenect_frame_mode mode =
          freenect_find_video_mode(FREENECT_RESOLUTION_MEDIUM, FREENECT_VIDEO_RGB);
      if (!mode.is_valid || freenect_set_video_mode(device_, mode) < 0) {
        Close();
        throw CaptureError(ErrorKind::kDeviceError, description_ + " rejects 640x480 RGB video");
      }
      freenect_set_video_callback(device_, &FreenectDevice::OnVideo);
      colour_ = StreamInfo{PixelFormat::kRgb24, 640, 480, 30};
    }
    if (options.depth) {
      freenect_depth_format format = FREENECT_DEPTH_REGISTERED;
      if (options.depth_mode == "registered") {
        format = FREENECT_DEPTH_REGISTERED;
      } else if (options.depth_mode == "mm") {
        format = FREENECT_DEPTH_MM;
      } else if (options.depth_mode == "raw") {
        format = FREENECT_DEPTH_11BIT;
      } else {
        Close();
        throw CaptureError(ErrorKind::kBadInput, "unknown depth_mode '" + options.depth_mode +
                                                     "' (expected registered, mm or raw)");
      }
      // Look the mode up in the library's list (fakenect lists only 11-bit and asserts when
      // freenect_find_depth_mode is asked for another format).
      freenect_frame_mode mode{};
      for (int i = 0; i < freenect_get_depth_mode_count(); ++i) {
        const freenect_frame_mode m = freenect_get_depth_mode(i);
        if (m.is_valid && m.resolution == FREENECT_RESOLUTION_MEDIUM && m.depth_format == format) {
          mode = m;
        }
      }
      if (!mode.is_valid) {
        for (int i = 0; i < freenect_get_depth_mode_count(); ++i) {
          const freenect_frame_mode m = freenect_get_depth_mode(i);
          if (m.is_valid && m.resolution == FREENECT_RESOLUTION_MEDIUM &&
              m.depth_format == FREENECT_DEPTH_11BIT) {
            mode = m;
          }
        }
      }
      if (!mode.is_valid || freenect_set_depth_mode(device_, mode) < 0) {
        Close();
        throw CaptureError(ErrorKind::kDeviceError,
                           description_ + " rejects depth mode " + options.depth_mode);
      }
      const freenect_frame_mode current = freenect_get_current_depth_mode(device_);
      depth_format_ =
          current.is_valid ? static_cast<freenect_depth_format>(current.depth_format) : format;
      if (depth_format_ != format) {
        log(description_ + ": libfreenect delivers 11-bit depth instead of '" + options.depth_mode +
            "' (fakenect, or no registration data): converting to mm here, depth NOT registered");
      }
      registered_ = depth_format_ == FREENECT_DEPTH_REGISTERED;
      const PixelFormat pixel =
          (depth_format_ == FREENECT_DEPTH_REGISTERED || depth_format_ == FREENECT_DEPTH_MM)
              ? PixelFormat::kDepthMm
              : PixelFormat::kKinectRaw11;
      freenect_set_depth_callback(device_, &FreenectDevice::OnDepth);
      depth_ = StreamInfo{pixel, 640, 480, 30};
    }
    // Frames land in our buffers (fakenect frees its own right after the callback; libfreenect
    // writes them only inside freenect_process_events, so they stay valid until the next Next()).
    colour_buffer_.resize(640 * 480 * 3);
    depth_buffer_.resize(640 * 480);
    if (options.colour) freenect_set_video_buffer(device_, colour_buffer_.data());
    if (options.depth) freenect_set_depth_buffer(device_, depth_buffer_.data());
    if ((options.depth && freenect_start_depth(device_) < 0) ||
        (options.colour && freenect_start_video(device_) < 0)) {
      Close();
      throw CaptureError(ErrorKind::kDeviceError,
                         description_ +
                             " does not start streaming: replug it (USB 2.0 port, "
                             "its own power adapter)");
    }
  }

  ~FreenectDevice() override { Close(); }

  const std::string& description() const override { return description_; }
  std::optional<StreamInfo> colour_stream() const override { return colour_; }
  std::optional<StreamInfo> depth_stream() const override { return depth_; }
  bool depth_registered() const override { return registered_; }
  std::optional<Intrinsics> factory_intrinsics() const override {
    // Kinect v1 RGB camera (OpenKinect calibration, typical unit).
    Intrinsics k;
    k.width = 640;
    k.height = 480;
    k.fx = 525.0;
    k.fy = 525.0;
    k.cx = 319.5;
    k.cy = 239.5;
    if (colour_ || registered_) return k;
    // Depth camera (unregistered depth only).
    k.fx = 580.0;
    k.fy = 580.0;
    return k;
  }

  bool Next(std::chrono::milliseconds timeout, FrameSet& frames) override {
    got_colour_ = got_depth_ = false;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!got_colour_ && !got_depth_) {
      const auto left = deadline - std::chrono::steady_clock::now();
      if (left <= std::chrono::nanoseconds(0)) return false;
      timeval tv{};
      const auto us = std::chrono::duration_cast<std::chrono::microseconds>(left).count();
      tv.tv_sec = us / 1'000'000;
      tv.tv_usec = us % 1'000'000;
      const int rc = freenect_process_events_timeout(context_, &tv);
      if (rc < 0) {
        throw CaptureError(ErrorKind::kDisconnected,
                           description_ + " stopped: libfreenect reports error " +
                               std::to_string(rc) +
                               " (unplugged, or the end of a fakenect recording): replug it");
      }
    }
    if (got_colour_) frames.colour = colour_frame_;
    if (got_depth_) frames.depth = depth_frame_;
    return true;
  }

 private:
  static void OnVideo(freenect_device* device, void* data, uint32_t timestamp) {
    auto* self = static_cast<FreenectDevice*>(freenect_get_user(device));
    RawFrame& f = self->colour_frame_;
    f.format = PixelFormat::kRgb24;
    f.width = 640;
    f.height = 480;
    f.stride = 640 * 3;
    f.data = {static_cast<const uint8_t*>(data), 640 * 480 * 3};
    f.stamp_mono_ns = MonotonicNowNs() - kHalfFrameNs;
    f.sequence = ++self->colour_count_;
    self->got_colour_ = true;
  }
  static void OnDepth(freenect_device* device, void* data, uint32_t timestamp) {
    auto* self = static_cast<FreenectDevice*>(freenect_get_user(device));
    RawFrame& f = self->depth_frame_;
    f.format = self->depth_->format;
    f.width = 640;
    f.height = 480;
    f.stride = 640 * 2;
    f.data = {static_cast<const uint8_t*>(data), 640 * 480 * 2};
    f.stamp_mono_ns = MonotonicNowNs() - kHalfFrameNs;
    f.sequence = ++self->depth_count_;
    self->got_depth_ = true;
  }

  void Close() {
    if (device_ != nullptr) {
      if (depth_) freenect_stop_depth(device_);
      if (colour_) freenect_stop_video(device_);
      freenect_close_device(device_);
      device_ = nullptr;
    }
    if (context_ != nullptr) {
      freenect_shutdown(context_);
      context_ = nullptr;
    }
  }

  freenect_context* context_ = nullptr;
  freenect_device* device_ = nullptr;
  std::string description_;
  std::optional<StreamInfo> colour_;
  std::optional<StreamInfo> depth_;
  freenect_depth_format depth_format_ = FREENECT_DEPTH_REGISTERED;
  bool registered_ = false;
  RawFrame colour_frame_;
  RawFrame depth_frame_;
  uint64_t colour_count_ = 0;
  uint64_t depth_count_ = 0;
  std::vector<uint8_t> colour_buffer_;
  std::vector<uint16_t> depth_buffer_;
  bool got_colour_ = false;
  bool got_depth_ = false;
};

}  // namespace

std::unique_ptr<Device> OpenFreenect(const FreenectOptions& options,
                                     const std::function<void(const std::string&)>& log) {
  return std::make_unique<FreenectDevice>(options, log);
}

}  // namespace probeless::capture
