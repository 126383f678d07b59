// Generic 3-D face model and head pose for the tracker.
//
// Face frame (msgs::FaceObservation::head_pose): origin at the nose bridge between the eyes (the
// nasion, iBUG landmark 27 lies 2 mm above it), x towards the subject's left ear (image right for a
// frontal face), y towards the chin, z into the head; millimetres in the table, metres in poses.
// A face looking straight into the camera has the identity rotation.
#pragma once

#include <array>
#include <span>

namespace probeless::face_track {

inline constexpr int kLandmarkCount = 68;

struct Point2f {
  float x = 0;
  float y = 0;
};

// Generic (average adult) positions of the 68 iBUG 300-W landmarks in the face frame, millimetres:
// inter-pupil distance 64 mm (eye centres at x = +-32), nose tip 32 mm and mouth centre 67 mm
// below the eyes (the proportions of the Yale B canonical crop, docs/face_light.md), depths from
// anthropometric averages. Written for this project (docs/face_light.md, "Head pose").
extern const std::array<std::array<float, 3>, kLandmarkCount> kGenericLandmarksMm;

// Rigid transform face frame -> camera frame: p_cam = rotation * p_face + translation (metres);
// rotation row-major.
struct HeadPose {
  std::array<double, 9> rotation{1, 0, 0, 0, 1, 0, 0, 0, 1};
  std::array<double, 3> translation{0, 0, 0};
  bool valid = false;
};

// solvePnP (iterative, from `guess` if valid, else EPnP) of the generic model against `landmarks`
// (pixels) with pinhole intrinsics; *rms_px (if not null) = RMS reprojection error in pixels.
// Returns an invalid pose if the solve fails or puts the face behind the camera.
HeadPose EstimateHeadPose(std::span<const Point2f> landmarks, double fx, double fy, double cx,
                          double cy, const HeadPose& guess, double* rms_px);

// Temporal filter of head poses: exponential smoothing of translation and rotation (quaternion
// nlerp), weight `smoothing` of the previous estimate (0 = off, < 1); a jump (> 25 degrees or
// > 0.1 m) resets it, as does Reset().
class PoseFilter {
 public:
  explicit PoseFilter(double smoothing = 0.5) : smoothing_(smoothing) {}
  HeadPose Update(const HeadPose& measured);
  void Reset() { state_.valid = false; }

 private:
  double smoothing_;
  HeadPose state_;
};

// Quaternion (w, x, y, z), w >= 0, of a row-major rotation matrix, and back.
std::array<double, 4> QuaternionFromMatrix(const std::array<double, 9>& r);
std::array<double, 9> MatrixFromQuaternion(const std::array<double, 4>& q);

}  // namespace probeless::face_track
