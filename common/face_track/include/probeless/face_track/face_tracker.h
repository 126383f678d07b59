// Face detection and 68-point landmark tracking for the face pipeline (docs/face_light.md, "Face
// tracking"): dlib's HOG detector (or OpenCV YuNet / a Haar cascade) finds the face, dlib's
// 68-point shape predictor places the iBUG 300-W landmarks, and between detections the predictor
// is re-run in a box derived from the previous landmarks (cheap steady state); a detection in a
// region around the face every `redetect_period` frames corrects drift and detects loss, a
// full-image detection runs while no face is tracked.
//
// Pixel frame everywhere: x right, y down, (0, 0) = centre of the top-left pixel.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>

#include "probeless/error/error.h"
#include "probeless/face_track/head_model.h"

namespace probeless::face_track {

// Bad input at the library's boundary (missing or unreadable model file, unknown backend, bad
// image or option): one line naming the thing and what was expected.
class FaceTrackError : public InputError {
 public:
  using InputError::InputError;
};

// Debian package paths of the models (libdlib-data; opencv-data for the Haar cascade).
inline constexpr const char* kDefaultShapePredictorPath =
    "/usr/share/dlib/shape_predictor_68_face_landmarks.dat";
inline constexpr const char* kDefaultHaarCascadePath =
    "/usr/share/opencv4/haarcascades/haarcascade_frontalface_default.xml";

enum class PixelFormat { kGray, kRgb, kBgr };

// A borrowed 8-bit image: row y starts at data + y * stride; 1 (gray) or 3 (RGB / BGR,
// interleaved) bytes per pixel.
struct ImageView {
  const uint8_t* data = nullptr;
  int width = 0;
  int height = 0;
  size_t stride = 0;  // bytes per row, >= width * Channels()
  PixelFormat format = PixelFormat::kGray;
  int Channels() const { return format == PixelFormat::kGray ? 1 : 3; }
};

enum class DetectorBackend { kDlibHog, kYuNet, kHaar };
// "dlib" | "yunet" | "haar" -> backend; throws FaceTrackError for any other name.
DetectorBackend BackendFromName(const std::string& name);

struct TrackerOptions {
  DetectorBackend backend = DetectorBackend::kDlibHog;
  // dlib 68-point shape predictor (iBUG 300-W; non-commercial licence, docs/face_light.md).
  std::string shape_predictor_path = kDefaultShapePredictorPath;
  std::string yunet_model_path;  // ONNX model for kYuNet (required for that backend)
  std::string haar_cascade_path = kDefaultHaarCascadePath;  // for kHaar
  // Detect in a region around the tracked face every this many frames (>= 1; 1 = detect every
  // frame); full-image detection whenever no face is tracked.
  int redetect_period = 10;
  // Full-image detection runs on the image downscaled to at most this width (pixels, >= 160);
  // faces narrower than ~80 px at that scale are not found by the HOG detector.
  int detect_max_width = 640;
  // Images smaller than this (either side, pixels) are padded (constant border at the image mean)
  // to it before detection, so tightly cropped faces (Yale B 168 x 192) get the context the
  // detectors need.
  int detect_min_size = 320;
  // Histogram-equalise the gray image the detector and the shape predictor see (not the sampled
  // image) when it is dark (mean < 50 of 255): finds faces in dim, backlit frames (the Yale B
  // ambient frames).
  bool equalize = true;
  // Contrast-limited adaptive histogram equalisation (tiles of ~80 px, this clip limit; 0 = off)
  // of the gray image the detector, the shape predictor and the flow see (not the sampled
  // image): restores the features of a half-lit face's dark side (face_orbit without flow
  // tracking: a face in 82 instead of 37 of 120 frames).
  double clahe_clip_limit = 4;
  // Tracking is lost when the landmark scale (inter-ocular distance) changes by more than this
  // factor between frames (> 1).
  double max_scale_change = 1.3;
  // Head-pose filter (PoseFilter): 0 = off, else the smoothing weight of the previous pose.
  double pose_smoothing = 0.5;
  // Optical-flow tracking between detections: the inner landmarks (17..67) are followed with
  // pyramidal Lucas-Kanade (forward-backward checked) and a RANSAC similarity of the surviving
  // points moves the previous landmarks. The shape predictor then runs in the box of the moved
  // landmarks; its result is kept if it agrees with them (median distance < flow_agreement x
  // inter-ocular distance), else the moved landmarks are reported (FaceTrack::flow). A region
  // re-detection that finds nothing no longer drops a face the flow still follows (a face lit
  // from the side, which the HOG detector misses). When fewer than flow_min_points points follow
  // the similarity (unrelated frames), the predictor runs in the previous box as without flow
  // (confidence 0.5) and a failed re-detection drops the face; after max_undetected_frames
  // frames without a successful detection the face is dropped too. false = the previous
  // behaviour (landmark tracking only, lost when a region detection fails).
  bool flow_tracking = true;
  int flow_min_points = 12;         // of the 51 inner landmarks (>= 3)
  double flow_agreement = 0.12;     // inter-ocular distances (> 0)
  int max_undetected_frames = 150;  // >= 1 (5 s at 30 fps)
};

// Pinhole intrinsics of the image (pixels), no distortion.
struct Intrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  // A guess for an uncalibrated camera: 60 degree horizontal field of view, centred.
  static Intrinsics Guess(int width, int height);
};

// What the tracker knows about the face in one frame.
struct FaceTrack {
  bool found = false;     // a face is tracked in this frame; false = nothing else is meaningful
  bool detected = false;  // this frame ran a detector that found the face (else landmark tracking)
  bool flow = false;      // landmarks moved by optical flow (the shape predictor disagreed)
  // [0, 1]: 1 for a detection; while tracking, the fraction of the inner landmarks that follow
  // the flow similarity, halved for flow-only landmarks, 0.5 without flow (false positives
  // cannot hide: a face kept without detection or predictor-flow agreement has confidence
  // <= 0.5). Without flow tracking (TrackerOptions::flow_tracking false) always 1.
  float confidence = 1;
  std::array<Point2f, kLandmarkCount> landmarks{};  // iBUG 300-W order, image pixels
  std::array<float, 4> box{};  // detector-style face box x, y, width, height (pixels)
  // The backend's own box (x, y, width, height, pixels; its convention: dlib HOG, YuNet or Haar)
  // when this frame ran a successful detection (detected), else zeros.
  std::array<float, 4> detection_box{};
  HeadPose pose;           // face frame -> camera frame (filtered)
  double pose_rms_px = 0;  // RMS reprojection error of the generic model (pixels)
};

// Detection + landmarks + head pose over a stream of frames. Not thread-safe; deterministic.
class FaceTracker {
 public:
  // Loads the models. Throws FaceTrackError "<what> model '<path>' not found (install Debian
  // package <pkg> ...)" for a missing file, "... cannot be read: <reason>" for a corrupt one, and
  // for out-of-range options.
  explicit FaceTracker(const TrackerOptions& options = {});
  ~FaceTracker();
  FaceTracker(const FaceTracker&) = delete;
  FaceTracker& operator=(const FaceTracker&) = delete;

  const TrackerOptions& options() const;
  // Processes the next frame of the stream. Throws FaceTrackError for an empty image or a stride
  // smaller than a row.
  FaceTrack Track(const ImageView& image, const Intrinsics& intrinsics);
  // Detection + landmarks on a single image, without tracking state (pose unfiltered).
  FaceTrack DetectOnce(const ImageView& image, const Intrinsics& intrinsics);
  // Forgets the tracked face (next Track detects in the whole image).
  void Reset();

  // Frames processed by Track so far, and how many of them ran a full-image / region detection.
  int64_t frames() const;
  int64_t full_detections() const;
  int64_t region_detections() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace probeless::face_track
