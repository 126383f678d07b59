// FaceObservation: a tracked face in one camera image (landmarks, head pose, shading samples).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "probeless/msgs/geometry.h"
#include "probeless/msgs/header.h"
#include "probeless/msgs/layout.h"

namespace probeless::msgs {

inline constexpr uint32_t kMaxFaceLandmarks = 68;
inline constexpr uint32_t kMaxFaceSamples = 512;

// One face seen in the image stamped header.stamp_* by the camera header.frame_id (camera optical
// frame: x right, y down, z forward). Fixed-size arrays (no payload): the whole message is
// sizeof(FaceObservation) = 13024 bytes; entries beyond landmark_count / sample_count are zero.
//
// Samples are points on the face surface chosen by the tracker (e.g. a fixed pattern on the face
// model): for each, the observed linear colour and the surface normal, so a light estimator needs
// no face model of its own.
struct FaceObservation {
  Header header;
  uint8_t face_detected = 0;    // 1 if a face was found; 0 = every other field is meaningless
  uint8_t reserved0[3] = {};    // zero
  uint32_t landmark_count = 0;  // valid entries of `landmarks`, 0..68 (68 = iBUG 300-W order)
  // Landmark i at pixel (landmarks[i][0], landmarks[i][1]) = (x right, y down) in the image of
  // header.frame_id; (0, 0) is the centre of the top-left pixel.
  float landmarks[kMaxFaceLandmarks][2] = {};
  // Head pose: transforms points from the face frame to the camera frame (translation in
  // metres). Face frame: origin at the nose bridge between the eyes, x towards the subject's left
  // ear, y towards the chin, z into the head; so a face looking straight into the camera has the
  // identity rotation (axes parallel to the camera's x right, y down, z forward).
  RigidTransform head_pose;
  uint32_t sample_count = 0;  // valid entries of the sample arrays, 0..512
  float quality = 0;          // overall tracking quality in [0, 1] (1 = best)
  // Sample i's observed colour: linear (de-gamma'd) R, G, B, each in [0, 1].
  float sample_rgb[kMaxFaceSamples][3] = {};
  // Sample i's unit surface normal (x, y, z) in the camera frame, pointing out of the face.
  float sample_normals[kMaxFaceSamples][3] = {};
  // Validity bitfield: sample i is valid iff bit (i % 64) of sample_valid[i / 64] is set
  // (occluded, saturated or off-image samples are invalid).
  uint64_t sample_valid[kMaxFaceSamples / 64] = {};

  static constexpr std::string_view kTypeName = "probeless_msgs/FaceObservation";
  static constexpr bool kHasPayload = false;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, FaceObservation, header);
    PROBELESS_MSGS_FIELD(b, FaceObservation, face_detected);
    PROBELESS_MSGS_FIELD(b, FaceObservation, reserved0);
    PROBELESS_MSGS_FIELD(b, FaceObservation, landmark_count);
    PROBELESS_MSGS_FIELD(b, FaceObservation, landmarks);
    PROBELESS_MSGS_FIELD(b, FaceObservation, head_pose);
    PROBELESS_MSGS_FIELD(b, FaceObservation, sample_count);
    PROBELESS_MSGS_FIELD(b, FaceObservation, quality);
    PROBELESS_MSGS_FIELD(b, FaceObservation, sample_rgb);
    PROBELESS_MSGS_FIELD(b, FaceObservation, sample_normals);
    PROBELESS_MSGS_FIELD(b, FaceObservation, sample_valid);
    return b.Finish<FaceObservation>();
  }

  // Whether sample i (< kMaxFaceSamples) is flagged valid. Throws MessageError for i out of range.
  bool SampleValid(uint32_t i) const {
    if (i >= kMaxFaceSamples) ThrowSampleIndex(i);
    return (sample_valid[i / 64] >> (i % 64)) & 1u;
  }
  // Sets or clears sample i's validity bit. Throws MessageError for i out of range.
  void SetSampleValid(uint32_t i, bool valid) {
    if (i >= kMaxFaceSamples) ThrowSampleIndex(i);
    const uint64_t bit = uint64_t{1} << (i % 64);
    sample_valid[i / 64] = valid ? (sample_valid[i / 64] | bit) : (sample_valid[i / 64] & ~bit);
  }
  // Number of valid samples among the first sample_count.
  uint32_t ValidSampleCount() const {
    uint32_t count = 0;
    for (uint32_t i = 0; i < sample_count && i < kMaxFaceSamples; ++i) {
      count += (sample_valid[i / 64] >> (i % 64)) & 1u;
    }
    return count;
  }

  // Throws MessageError unless landmark_count <= 68, sample_count <= 512, no validity bit is set
  // at or beyond sample_count, face_detected is 0 or 1 and quality is in [0, 1].
  void Validate() const {
    const std::string name(kTypeName);
    if (landmark_count > kMaxFaceLandmarks) {
      throw MessageError(name + ": landmark_count " + std::to_string(landmark_count) + " exceeds " +
                         std::to_string(kMaxFaceLandmarks));
    }
    if (sample_count > kMaxFaceSamples) {
      throw MessageError(name + ": sample_count " + std::to_string(sample_count) + " exceeds " +
                         std::to_string(kMaxFaceSamples));
    }
    for (uint32_t i = sample_count; i < kMaxFaceSamples; ++i) {
      if ((sample_valid[i / 64] >> (i % 64)) & 1u) {
        throw MessageError(name + ": sample " + std::to_string(i) +
                           " flagged valid but sample_count is " + std::to_string(sample_count));
      }
    }
    if (face_detected > 1) throw MessageError(name + ": face_detected must be 0 or 1");
    if (!(quality >= 0 && quality <= 1)) throw MessageError(name + ": quality must be in [0, 1]");
  }

 private:
  [[noreturn]] static void ThrowSampleIndex(uint32_t i) {
    throw MessageError(std::string(kTypeName) + ": sample index " + std::to_string(i) +
                       " out of range (max " + std::to_string(kMaxFaceSamples - 1) + ")");
  }
};
inline constexpr uint64_t FaceObservation::kLayoutHash =
    layout::Fnv1a64(FaceObservation::LayoutDescription());

static_assert(Message<FaceObservation>);
static_assert(sizeof(FaceObservation) == 13024 && alignof(FaceObservation) == 8);
static_assert(offsetof(FaceObservation, face_detected) == 56 &&
              offsetof(FaceObservation, landmark_count) == 60 &&
              offsetof(FaceObservation, landmarks) == 64 &&
              offsetof(FaceObservation, head_pose) == 608 &&
              offsetof(FaceObservation, sample_count) == 664 &&
              offsetof(FaceObservation, quality) == 668 &&
              offsetof(FaceObservation, sample_rgb) == 672 &&
              offsetof(FaceObservation, sample_normals) == 6816 &&
              offsetof(FaceObservation, sample_valid) == 12960);

}  // namespace probeless::msgs
