// CaptureError: the one exception type of probeless_capture, with a kind that tells a node whether
// waiting and reopening (param `retry: true`) can help.
#pragma once

#include <stdexcept>
#include <string>
#include <string_view>

#include "probeless/error/error.h"

namespace probeless::capture {

// Why a device could not be opened or stopped delivering.
enum class ErrorKind {
  kBadInput,      // wrong parameter, malformed calibration file, unsupported format: never retried
  kNoDevice,      // the device does not exist (yet): retried with `retry: true`
  kBusy,          // another process holds the device: retried
  kPermission,    // no access rights (udev rules / group membership): not retried
  kDisconnected,  // the device went away or stopped delivering frames: retried
  kDeviceError,   // any other driver failure: retried
};

// "bad input", "no device", "busy", "permission denied", "disconnected", "device error".
std::string_view ErrorKindName(ErrorKind kind);

// One line naming the device and what to do, e.g. "V4L2 device '/dev/video3' does not exist: plug
// the camera in or pick another with param 'device' (ls /dev/v4l/by-id)".
class CaptureError : public InputError {
 public:
  CaptureError(ErrorKind kind, const std::string& message) : InputError(message), kind_(kind) {}
  ErrorKind kind() const { return kind_; }
  // Whether waiting and reopening may help (no device, busy, disconnected, device error).
  bool retryable() const {
    return kind_ != ErrorKind::kBadInput && kind_ != ErrorKind::kPermission;
  }

 private:
  ErrorKind kind_;
};

}  // namespace probeless::capture
