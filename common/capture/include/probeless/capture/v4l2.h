// V4L2 (UVC webcams and other video-capture devices) through libv4l2: device lookup by path or by
// name/serial (/dev/v4l/by-id), format negotiation, camera controls, mmap streaming. The pure
// parts (lookup, negotiation, control mapping) are separate functions so they are testable without
// a device. <linux/videodev2.h> and libv4l2.h stay in src/v4l2_device.cpp.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "probeless/capture/device.h"

namespace probeless::capture {

// Camera controls as node params. Unset = leave the camera's value. exposure_time_us, gain and
// white_balance_temperature_k imply the matching auto mode off.
struct V4l2Controls {
  std::optional<bool> auto_exposure;       // V4L2_CID_EXPOSURE_AUTO: manual / aperture priority
  std::optional<double> exposure_time_us;  // V4L2_CID_EXPOSURE_ABSOLUTE (100 us units)
  std::optional<bool> auto_white_balance;  // V4L2_CID_AUTO_WHITE_BALANCE
  std::optional<int64_t> white_balance_temperature_k;  // V4L2_CID_WHITE_BALANCE_TEMPERATURE
  std::optional<bool> auto_gain;                       // V4L2_CID_AUTOGAIN
  std::optional<int64_t> gain;                         // V4L2_CID_GAIN
  std::optional<bool> auto_focus;                      // V4L2_CID_FOCUS_AUTO
  std::optional<int64_t> focus_absolute;               // V4L2_CID_FOCUS_ABSOLUTE
  std::optional<int64_t> brightness;                   // V4L2_CID_BRIGHTNESS
  std::optional<int64_t> contrast;                     // V4L2_CID_CONTRAST
  std::optional<int64_t> saturation;                   // V4L2_CID_SATURATION
  std::optional<int64_t> power_line_frequency;  // V4L2_CID_POWER_LINE_FREQUENCY 0 off,1 50,2 60 Hz
  // Let the automatic exposure, white balance and gain settle for lock_after_s seconds after
  // streaming starts, then switch those of them that were not set explicitly to manual (keeping
  // the converged values where the driver does): a fixed camera response for light estimation.
  bool lock_auto = true;
  double lock_after_s = 2.0;
};

// One control write: V4L2 control id and value, in the order they must be applied (auto modes
// before the manual values they unlock).
struct ControlWrite {
  uint32_t id = 0;
  int64_t value = 0;
  std::string name;  // the param name, for messages
};
// The writes for the explicitly set controls of `controls` (not the deferred lock).
std::vector<ControlWrite> MapControls(const V4l2Controls& controls);
// The writes that lock what `controls` leaves automatic (applied after lock_after_s).
std::vector<ControlWrite> LockControls(const V4l2Controls& controls);

// A format the device offers (or that was chosen).
struct FormatOption {
  PixelFormat format = PixelFormat::kYuyv;
  uint32_t width = 0;
  uint32_t height = 0;
  double fps = 0;  // 0 = unknown
};
// The best offer for `width` x `height` @ `fps` in `format` ("auto" = mjpeg, yuyv, rgb24, bgr24,
// grey in this order of preference for sizes above 640x480, yuyv first up to it): the exact size if
// offered, else the closest size; among equal sizes the closest rate. Throws CaptureError
// (kBadInput) naming the device and listing the offers when no offer has the format.
FormatOption ChooseFormat(const std::vector<FormatOption>& offers, const std::string& format,
                          uint32_t width, uint32_t height, double fps, const std::string& device);

// The device node for `spec`: a path (starting with '/') as is; otherwise the entry of `by_id_dir`
// whose name contains `spec` (case-insensitive; name or serial), preferring "-video-index0".
// Throws CaptureError(kNoDevice) listing the entries when none matches, kBadInput when several
// cameras match.
std::string ResolveV4l2Device(const std::string& spec,
                              const std::string& by_id_dir = "/dev/v4l/by-id");

struct V4l2Options {
  std::string device = "/dev/video0";  // path, or name/serial (see ResolveV4l2Device)
  std::string by_id_dir = "/dev/v4l/by-id";
  uint32_t width = 640;
  uint32_t height = 480;
  double fps = 30;
  std::string pixel_format = "auto";  // auto, mjpeg, yuyv, rgb24, bgr24, grey
  uint32_t buffers = 4;               // mmap buffers
  V4l2Controls controls;
};
// Opens, negotiates and starts streaming. Errors (CaptureError): no such device (kNoDevice),
// EACCES (kPermission: group 'video'), EBUSY (kBusy), not a capture device or no usable format
// (kBadInput). A frame-less or vanished device in Next() throws kDisconnected.
std::unique_ptr<Device> OpenV4l2(const V4l2Options& options,
                                 const std::function<void(const std::string&)>& log);

// --- libcamera ---------------------------------------------------------------------------------

struct LibcameraOptions {
  std::string camera_id;  // "" = first camera; else an id from ListLibcameraCameras (or a part)
  uint32_t width = 640;
  uint32_t height = 480;
  std::string pixel_format = "auto";       // auto (RGB888/BGR888/YUYV/MJPEG, first supported), ...
  std::optional<double> exposure_time_us;  // controls::ExposureTime (AeEnable off)
  std::optional<double> analogue_gain;     // controls::AnalogueGain
  std::optional<bool> auto_exposure;       // controls::AeEnable
  std::optional<bool> auto_white_balance;  // controls::AwbEnable (false = lock)
  uint32_t buffers = 4;
};
// Ids of the cameras libcamera finds ("" entries never). Throws CaptureError(kDeviceError) if
// the camera manager does not start.
std::vector<std::string> ListLibcameraCameras();
std::unique_ptr<Device> OpenLibcamera(const LibcameraOptions& options,
                                      const std::function<void(const std::string&)>& log);

}  // namespace probeless::capture
