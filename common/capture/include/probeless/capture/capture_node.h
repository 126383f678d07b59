// The loop every capture node runs: open the device (waiting and retrying when param `retry` is
// true), publish each frame into loaned bus slots (`image`, `depth`, `camera_info`, node-relative),
// detect a device that stops delivering within `stall_timeout_s`, reopen after unplug/replug, and
// stop promptly on SIGINT/SIGTERM.
//
// Common params read here: frame_id ("camera"), camera_info_url (calibration file, "" = device
// factory values or a field-of-view default, logged), default_fov_deg (60), retry (false),
// retry_period_s (1.0), stall_timeout_s (1.0), max_frames (0 = unlimited; exit 0 after that many
// colour-or-depth frame sets), slots (8). Topics: image, depth, camera_info (remappable).
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "probeless/bus/bus.h"
#include "probeless/capture/device.h"
#include "probeless/node/node.h"

namespace probeless::capture {

// Publishes frame sets of one device: converts each frame straight into a loaned slot of its
// topic, stamps header.stamp_mono_ns with the frame's mid-exposure time and header.stamp_ns with
// the same instant on CLOCK_REALTIME, and publishes a CameraInfo with the colour frame's stamp
// (or the depth frame's, for depth-only devices).
class FramePublisher {
 public:
  // Publishers may be null for streams the device does not have. `intrinsics` are for the colour
  // image (and the depth image when registered); `depth_scale` 0.001 when depth is published.
  FramePublisher(bus::Publisher* image, bus::Publisher* depth, bus::Publisher* camera_info,
                 const Intrinsics& intrinsics, double depth_scale, const std::string& frame_id);
  // Publishes the frames present in `frames`. Throws CaptureError(kBadInput) on a frame that does
  // not convert (corrupt MJPEG).
  void Publish(const FrameSet& frames);
  uint64_t published_colour() const { return colour_count_; }
  uint64_t published_depth() const { return depth_count_; }

 private:
  void PublishImage(bus::Publisher& publisher, const RawFrame& frame, uint64_t sequence);
  void PublishInfo(int64_t stamp_mono_ns, uint64_t sequence);
  bus::Publisher* image_;
  bus::Publisher* depth_;
  bus::Publisher* camera_info_;
  Intrinsics intrinsics_;
  double depth_scale_;
  std::string frame_id_;
  uint64_t colour_count_ = 0;
  uint64_t depth_count_ = 0;
};

// Opens the device; throws CaptureError.
using DeviceOpener = std::function<std::unique_ptr<Device>()>;

// Runs the capture loop of `node` (see the top of this file) until shutdown, max_frames, or a
// fatal error. Returns the process exit code: 0 on shutdown or after max_frames, 1 when the device
// fails (or cannot be opened) and retry is off or the error is not retryable (bad input,
// permission): the error is logged as one line naming the device and what to do.
int RunCaptureNode(node::Node& node, const DeviceOpener& open);

}  // namespace probeless::capture
