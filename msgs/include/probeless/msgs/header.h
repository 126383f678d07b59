// Header: the stamp, frame and sequence that start every probeless message.
#pragma once

#include <time.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "probeless/msgs/layout.h"

namespace probeless::msgs {

// Time and frame of the data a message carries (not of its publication: the bus stamps that
// separately in bus::MessageInfo).
struct Header {
  // Acquisition time (middle of exposure for images) in nanoseconds since the Unix epoch,
  // CLOCK_REALTIME. Use for cross-machine alignment and recordings.
  int64_t stamp_ns = 0;
  // The same instant on CLOCK_MONOTONIC, nanoseconds. Use for latency and rate measurements.
  int64_t stamp_mono_ns = 0;
  // Producer-assigned sequence number of the data (frame counter), starting at 1; 0 = unset.
  uint64_t sequence = 0;
  // Coordinate frame of the data, NUL-terminated, at most 31 characters (e.g. "camera_optical").
  // Frame conventions: see docs/messages.md (camera frames are x right, y down, z forward).
  char frame_id[kFrameIdCapacity] = {};

  static constexpr std::string_view kTypeName = "probeless_msgs/Header";
  static constexpr bool kHasPayload = false;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, Header, stamp_ns);
    PROBELESS_MSGS_FIELD(b, Header, stamp_mono_ns);
    PROBELESS_MSGS_FIELD(b, Header, sequence);
    PROBELESS_MSGS_FIELD(b, Header, frame_id);
    return b.Finish<Header>();
  }

  // The frame id as text.
  std::string_view FrameId() const { return FixedString(frame_id); }
  // Sets the frame id; throws MessageError if it has more than 31 characters.
  void SetFrameId(std::string_view id) { SetFixedString(frame_id, id, "frame_id"); }
  // Sets both stamps to the current time (CLOCK_REALTIME and CLOCK_MONOTONIC, read back to back).
  void StampNow() {
    timespec wall{};
    timespec mono{};
    clock_gettime(CLOCK_REALTIME, &wall);
    clock_gettime(CLOCK_MONOTONIC, &mono);
    stamp_ns = static_cast<int64_t>(wall.tv_sec) * 1'000'000'000 + wall.tv_nsec;
    stamp_mono_ns = static_cast<int64_t>(mono.tv_sec) * 1'000'000'000 + mono.tv_nsec;
  }
};
inline constexpr uint64_t Header::kLayoutHash = layout::Fnv1a64(Header::LayoutDescription());

static_assert(Message<Header>);
static_assert(sizeof(Header) == 56 && alignof(Header) == 8);
static_assert(offsetof(Header, stamp_ns) == 0 && offsetof(Header, stamp_mono_ns) == 8 &&
              offsetof(Header, sequence) == 16 && offsetof(Header, frame_id) == 24);

}  // namespace probeless::msgs
