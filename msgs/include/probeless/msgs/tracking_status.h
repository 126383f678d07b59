// TrackingStatus: the camera tracker's verdict on one frame (fusion, `scene/tracking`).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "probeless/msgs/header.h"
#include "probeless/msgs/layout.h"

namespace probeless::msgs {

// The tracking state of one frame (recon::TrackingState without "empty").
enum class TrackingStatusState : uint32_t {
  kInvalid = 0,
  kTracked = 1,    // the pose passed the quality test; the frame was integrated
  kUncertain = 2,  // the pose is doubtful: scene/pose published, the frame not integrated
  kLost = 3,       // no pose (scene/pose not published), not integrated; relocalising
};
constexpr std::string_view DescribeEnum(TrackingStatusState) {
  return "TrackingStatusState{invalid=0,tracked=1,uncertain=2,lost=3}";
}

// Bits of TrackingStatus::reasons (the same values as recon::TrackingReason).
inline constexpr uint32_t kTrackingReasonIcpFailed = 1u << 0;     // ICP's own test failed
inline constexpr uint32_t kTrackingReasonResidual = 1u << 1;      // residual vs running mean
inline constexpr uint32_t kTrackingReasonInliers = 1u << 2;       // inliers vs running mean
inline constexpr uint32_t kTrackingReasonMotion = 1u << 3;        // off constant velocity
inline constexpr uint32_t kTrackingReasonDegenerate = 1u << 4;    // a pose direction unobserved
inline constexpr uint32_t kTrackingReasonPersistent = 1u << 5;    // uncertain too long
inline constexpr uint32_t kTrackingReasonRelocalising = 1u << 6;  // no relocalisation yet

// Capacity of TrackingStatus::reason_text in bytes, including the terminating NUL.
inline constexpr size_t kTrackingReasonCapacity = 192;

// One per frame fusion processes, with the depth frame's header, published before that frame's
// scene/pose and scene/gbuffer. The cue values are those of recon::TrackingQuality (0 where a
// cue did not apply: the first frame, warm-up); the counts run since the node started (a reset
// does not clear them).
struct TrackingStatus {
  Header header;  // the depth frame's header
  TrackingStatusState state = TrackingStatusState::kInvalid;
  float score = 0;                 // in [0, 1]: >= 0.5 tracked, 0 lost
  uint32_t reasons = 0;            // kTrackingReason* bits
  uint8_t integrated = 0;          // 0/1: fused into the volume
  uint8_t relocalised = 0;         // 0/1: tracking resumed on this frame
  uint8_t reserved0[2] = {};       // zero
  float rms_m = 0;                 // ICP point-to-plane RMS, metres
  float inlier_fraction = 0;       // ICP pairs / valid pixels, 0..1
  float residual_ratio = 0;        // rms / its running mean
  float inlier_ratio = 0;          // inliers / their running mean
  float motion_translation_m = 0;  // off the constant-velocity step, m
  float motion_rotation_deg = 0;   // off the constant-velocity step, deg
  float observability = 0;         // weakest pose direction, 0..1
  uint32_t reserved1 = 0;          // zero
  uint64_t frames = 0;             // frames processed, this one included
  uint64_t tracked_frames = 0;
  uint64_t uncertain_frames = 0;
  uint64_t lost_frames = 0;
  uint64_t relocalisations = 0;
  char reason_text[kTrackingReasonCapacity] = {};  // NUL-terminated one line; "" when tracked

  static constexpr std::string_view kTypeName = "probeless_msgs/TrackingStatus";
  static constexpr bool kHasPayload = false;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, header);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, state);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, score);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, reasons);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, integrated);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, relocalised);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, reserved0);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, rms_m);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, inlier_fraction);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, residual_ratio);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, inlier_ratio);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, motion_translation_m);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, motion_rotation_deg);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, observability);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, reserved1);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, frames);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, tracked_frames);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, uncertain_frames);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, lost_frames);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, relocalisations);
    PROBELESS_MSGS_FIELD(b, TrackingStatus, reason_text);
    return b.Finish<TrackingStatus>();
  }

  std::string_view ReasonText() const { return FixedString(reason_text); }
  // Stores `text`, cut to kTrackingReasonCapacity - 1 characters (a reason is diagnostic text:
  // a long one is shortened, not refused).
  void SetReasonText(std::string_view text) {
    SetFixedString(reason_text, text.substr(0, kTrackingReasonCapacity - 1), "reason_text");
  }
  // Throws MessageError naming the field: an unknown state, a score outside [0, 1] or not
  // finite, a flag other than 0/1, or an unterminated reason_text.
  void Validate() const {
    if (state != TrackingStatusState::kTracked && state != TrackingStatusState::kUncertain &&
        state != TrackingStatusState::kLost) {
      throw MessageError("probeless_msgs/TrackingStatus: state " +
                         std::to_string(static_cast<uint32_t>(state)) +
                         " is not tracked (1), uncertain (2) or lost (3)");
    }
    if (!(score >= 0.0f && score <= 1.0f)) {
      throw MessageError("probeless_msgs/TrackingStatus: score " + std::to_string(score) +
                         " is outside [0, 1]");
    }
    if (integrated > 1 || relocalised > 1) {
      throw MessageError(
          "probeless_msgs/TrackingStatus: integrated and relocalised must be 0 or 1");
    }
    if (reason_text[kTrackingReasonCapacity - 1] != '\0') {
      throw MessageError("probeless_msgs/TrackingStatus: reason_text is not NUL-terminated");
    }
  }
};
inline constexpr uint64_t TrackingStatus::kLayoutHash =
    layout::Fnv1a64(TrackingStatus::LayoutDescription());

static_assert(Message<TrackingStatus>);
static_assert(sizeof(TrackingStatus) == 336 && alignof(TrackingStatus) == 8);
static_assert(offsetof(TrackingStatus, frames) == 104 &&
              offsetof(TrackingStatus, reason_text) == 144);

}  // namespace probeless::msgs
