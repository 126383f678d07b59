// The thin device interface every capture backend implements (V4L2, libcamera, OpenNI2,
// libfreenect), the clocks a backend stamps frames with, and the backends' constructors.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>

#include "probeless/capture/convert.h"
#include "probeless/capture/intrinsics.h"
#include "probeless/capture/registration.h"

namespace probeless::capture {

// Size, format and rate of one stream of an open device.
struct StreamInfo {
  PixelFormat format = PixelFormat::kRgb24;
  uint32_t width = 0;  // pixels
  uint32_t height = 0;
  double fps = 0;  // frames per second the device was configured for; 0 = unknown
};

// What one Device::Next() delivered: a colour frame, a depth frame, or both (synchronised).
// The frames' data stay valid until the next call of Next() (or the device's destruction).
struct FrameSet {
  std::optional<RawFrame> colour;
  std::optional<RawFrame> depth;
};

// An open capture device. Not thread-safe: one thread calls Next() in a loop. The destructor
// stops streaming and releases the device without blocking for long (< 1 s).
class Device {
 public:
  virtual ~Device() = default;
  // One line for logs and errors, e.g. "V4L2 device '/dev/video0' (HD Pro Webcam C920)".
  virtual const std::string& description() const = 0;
  virtual std::optional<StreamInfo> colour_stream() const = 0;
  virtual std::optional<StreamInfo> depth_stream() const = 0;
  // Whether depth frames are registered to the colour camera (same size and intrinsics).
  virtual bool depth_registered() const { return false; }
  // The colour camera's factory intrinsics, if the device stores them.
  virtual std::optional<Intrinsics> factory_intrinsics() const { return std::nullopt; }
  // Waits at most `timeout` for the next frame(s); false on timeout. Throws CaptureError
  // (kDisconnected, kDeviceError) when the device fails or goes away.
  virtual bool Next(std::chrono::milliseconds timeout, FrameSet& frames) = 0;
};

// CLOCK_MONOTONIC and CLOCK_REALTIME now, nanoseconds.
int64_t MonotonicNowNs();
int64_t RealtimeNowNs();
// The CLOCK_REALTIME instant of monotonic time `mono_ns` (offset read now).
int64_t RealtimeFromMonotonic(int64_t mono_ns);

// Maps a device's own frame clock (e.g. OpenNI2's microsecond timestamps, libfreenect's 60 MHz
// counter) to CLOCK_MONOTONIC: offset = the smallest (arrival - device time) seen over the last
// `window` frames (the transport latency's lower bound), so stamps follow the device's exposure
// clock without the jitter of arrival times. `latency_ns` is subtracted on top (readout + half
// exposure when known).
class DeviceClock {
 public:
  explicit DeviceClock(int64_t latency_ns = 0, int window = 120)
      : latency_ns_(latency_ns), window_(window) {}
  // Monotonic time of device time `device_ns`, given the frame arrived at `arrival_mono_ns`.
  int64_t ToMonotonic(int64_t device_ns, int64_t arrival_mono_ns);
  void Reset() { count_ = 0; }

 private:
  int64_t latency_ns_;
  int window_;
  int count_ = 0;
  int64_t offset_ = 0;
  int64_t last_device_ns_ = 0;
};

// --- Backends (each in its own .cpp; driver headers stay there) ---------------------------------

// libfreenect (Kinect v1): device index or serial; depth "registered" (FREENECT_DEPTH_REGISTERED,
// mm in the RGB camera's frame), "mm" (FREENECT_DEPTH_MM, depth camera's frame) or "raw" (11-bit,
// converted here with KinectDepthModel). Falls back to "raw" (logged through `log`) when the
// library keeps delivering 11-bit (fakenect). tilt_deg in [-30, 30] or NaN = leave; led 0..6
// (freenect_led_options) or -1 = leave.
struct FreenectOptions {
  std::string device;  // "" or "0" = first; a number = index; else a serial
  std::string depth_mode = "registered";
  bool colour = true;
  bool depth = true;
  double tilt_deg = std::numeric_limits<double>::quiet_NaN();
  int led = -1;
};
std::unique_ptr<Device> OpenFreenect(const FreenectOptions& options,
                                     const std::function<void(const std::string&)>& log);

// OpenNI2 (PrimeSense, Asus Xtion, Orbbec, Kinect via drivers, .oni recordings): URI ("" = any
// device; a path ending in .oni = a recording); 640x480@30 depth in mm and RGB by default;
// hardware registration when supported, else software registration (RegisterDepthToColour) with
// the factory fields of view and `depth_to_colour`; frame sync on; mirroring off.
struct OpenNi2Options {
  std::string uri;
  uint32_t width = 640;
  uint32_t height = 480;
  double fps = 30;
  bool colour = true;
  bool depth = true;
  std::string registration = "auto";  // "auto" (hardware, else software), "hardware", "software",
                                      // "off"
  DepthToColour depth_to_colour{{1, 0, 0, 0, 1, 0, 0, 0, 1}, {-0.025, 0, 0}};
  bool loop_recording = false;  // .oni only: replay from the start at its end
};
std::unique_ptr<Device> OpenOpenNi2(const OpenNi2Options& options,
                                    const std::function<void(const std::string&)>& log);

}  // namespace probeless::capture
