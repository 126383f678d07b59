// scene_light's auxiliary views (use_aux): the views fusion publishes on scene/aux, matched to a
// G_r by exact stamp with a bounded wait (they come from fusion just before their G_r).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>

#include "probeless/bus/bus.h"
#include "probeless/light/transfer.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/node.h"

namespace probeless::scene_light {

// The views one frame uses: `buffers` borrows the payload of `sample` (none: empty buffers).
struct FrameAuxViews {
  std::optional<bus::Sample> sample;
  light::AuxiliaryBuffers buffers;
};

class AuxViewQueue {
 public:
  // Subscribes scene/aux (queue depth 8); a frame waits at most `wait` for its views.
  AuxViewQueue(node::Node& node, std::chrono::milliseconds wait);

  // The subscriber, for Spin: views that arrive while no G_r is being processed are handed to
  // Hold, so lock-step replay never waits on an unacked view.
  bus::Subscriber& subscriber() { return sub_; }
  // Keeps a received sample (the newest kKept; older ones are released).
  void Hold(bus::Sample&& s);
  // Fills `out` with the views of the frame of `header` (its stamp): the held or arriving views
  // with that stamp, waiting up to the wait while none as new arrived; views older than it are
  // released. None: the first time one warning, counted as missing. A malformed message: one
  // error line naming the frame, counted as malformed, `out->buffers` empty.
  void ForFrame(const msgs::Header& header, FrameAuxViews* out);
  // Releases every held view (a restarted source: they never match).
  void Clear() { queue_.clear(); }
  // One info line: frames with views, without, with a malformed message.
  void LogSummary() const;

 private:
  // Held samples (the bus allows 16 per process).
  static constexpr size_t kKept = 8;
  std::optional<bus::Sample> Take(int64_t stamp);

  node::Node& node_;
  std::chrono::milliseconds wait_;
  bus::Subscriber sub_;
  std::deque<bus::Sample> queue_;  // received views not yet matched, oldest first
  int64_t used_ = 0, missing_ = 0, bad_ = 0;
};

}  // namespace probeless::scene_light
