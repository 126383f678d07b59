// Sampling a face_light model's positions on a tracked face (docs/face_light.md, "Sampling"): the
// landmarks define the similarity transform from the canonical crop frame (face_light/model.h)
// to the image, each sample is the box-filtered patch of face_light::SamplePatches per channel,
// and every sample gets a validity with the reason it was rejected.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "probeless/face_light/model.h"
#include "probeless/face_track/face_tracker.h"

namespace probeless::msgs {
struct FaceObservation;
struct Image;
}  // namespace probeless::msgs

namespace probeless::face_track {

// Why a sample is invalid (bit set), 0 = valid.
enum SampleFlag : uint8_t {
  kOutsideImage = 1,   // the patch leaves the image
  kSaturated = 2,      // a patch pixel reaches the saturation level
  kTooDark = 4,        // channel-mean value below dark_level
  kFacingAway = 8,     // the surface normal faces away from the camera (pose occlusion)
  kInconsistent = 16,  // differs from the median of its neighbours by more than the threshold
};

struct SamplerOptions {
  int saturation_level = 255;  // 0..256, a patch pixel >= this is saturated (256 = off)
  double dark_level = 0.01;    // channel-mean patch value (0..1) below this is too dark
  // A sample whose normal makes cos(angle to the viewing ray) below this is facing away.
  double min_facing_cosine = 0.15;
  // Neighbour consistency: |value - median of the neighbours| > this (0..1 units) rejects;
  // 0 = off. Neighbours: the `neighbours` nearest samples in the canonical crop.
  double neighbour_threshold = 0.35;
  int neighbours = 6;
  // Landmarks fitted to the canonical crop: false = the paper's eye-based frame (two eye
  // centres), true = eyes, nose tip and mouth centre (least squares over 4 points).
  bool four_point_frame = true;
  // The image is sRGB-encoded (webcams, the simulator's renders): each patch mean is decoded to
  // linear (IEC 61966-2-1) before it is stored, so the estimator gets the (roughly linear) units of
  // the Yale B pixels the shipped model was trained on. false = the values as they are (Yale B).
  // dark_level and neighbour_threshold then apply to the linear values.
  bool srgb_input = false;
};

// The samples of one frame, in model order.
struct FaceSamples {
  int count = 0;
  std::vector<float> rgb;  // [3 i + c], patch mean / 255 of R, G, B (gray: R = G = B), sRGB-decoded
                           // with SamplerOptions::srgb_input
  std::vector<uint8_t> flags;                     // SampleFlag bits, 0 = valid
  std::vector<float> normals;                     // [3 i + k], unit normal in the camera frame
  std::vector<float> image_points;                // [2 i + k], patch centre x, y in image pixels
  face_light::SimilarityTransform crop_to_image;  // canonical crop pixels -> image pixels
  float quality = 0;                              // [0, 1], see FaceSampler::Sample
  int ValidCount() const;
};

// The canonical crop landmarks (face_light::kCanonical*) as iBUG combinations: right eye centre =
// mean of 36..41, left eye centre = mean of 42..47, nose tip = 30, mouth centre = mean of 60..67.
std::array<face_light::Point2, 4> CanonicalLandmarks(std::span<const Point2f> landmarks);

// The CanonicalLandmarks combinations of dlib's 68 landmarks on the canonical crop (crop pixels),
// measured as the mean over the Yale B frontal-lit crops the tracker finds (face_track_data_test):
// dlib's eye-contour centres sit ~5 px below face_light's kCanonical*Eye points (which mark the
// pupils / eyelid line of the mean crop), so the fit uses these to map a Yale B crop onto itself.
inline constexpr std::array<face_light::Point2, 4> kTrackerCanonical{
    face_light::Point2{34.2, 49.0}, face_light::Point2{130.0, 49.3}, face_light::Point2{81.6, 94.3},
    face_light::Point2{81.3, 147.2}};

// The similarity from canonical crop pixels to image pixels the sampler uses for landmarks:
// FitSimilarity of kTrackerCanonical onto their CanonicalLandmarks (four points, or the two eyes
// with four_point = false).
face_light::SimilarityTransform CanonicalToImage(std::span<const Point2f> landmarks,
                                                 bool four_point = true);

class FaceSampler {
 public:
  // Precomputes per sample its face-frame point and normal (an ellipsoid head fitted to the
  // canonical crop: docs/face_light.md) and its neighbours. Throws FaceTrackError for options out
  // of range.
  FaceSampler(const face_light::FaceLightModel& model, const SamplerOptions& options = {});

  int SampleCount() const { return static_cast<int>(positions_.size()); }
  // Samples `image` for a found track. quality = (valid / count) * clamp(1 - fit_rms / (0.05 *
  // inter-ocular distance), 0, 1) * track.confidence, fit_rms = RMS residual of the
  // canonical-landmark similarity fit (pixels). Throws FaceTrackError if !track.found or the
  // image is empty.
  FaceSamples Sample(const ImageView& image, const FaceTrack& track) const;

  // Face-frame sample points (metres) and unit normals, model order.
  const std::vector<std::array<double, 3>>& points() const { return points_; }
  const std::vector<std::array<double, 3>>& face_normals() const { return normals_; }

 private:
  face_light::FaceLightModel model_;
  SamplerOptions options_;
  std::vector<face_light::Point2> positions_;
  std::vector<std::array<double, 3>> points_;
  std::vector<std::array<double, 3>> normals_;
  std::vector<int> neighbours_;  // [i * options_.neighbours + k]
};

// The tracker's view of a bus image (msgs::Image with its payload; no copy: the view points into
// `payload`, which must outlive it). rgb8, bgr8 and mono8 map to kRgb, kBgr and kGray. Throws
// msgs::MessageError for a message whose payload does not hold it (Image::Validate) and
// "face_tracker: image encoding <name> not supported (expected rgb8, bgr8 or mono8)".
ImageView ViewOfImage(const msgs::Image& image, std::span<const std::byte> payload);

// Fills a FaceObservation (header left to the caller): face_detected, 68 landmarks, head_pose,
// samples (rgb, camera-frame normals, validity bits) and quality. A track that is not found
// gives face_detected = 0 and everything else zero.
void FillObservation(const FaceTrack& track, const FaceSamples* samples,
                     msgs::FaceObservation& out);

// Draws the samples (green valid, red invalid), the landmarks (yellow) and the head axes onto an
// RGB copy of `image` (paper figure 1c): out = width * height * 3 bytes, rgb8.
void DrawDebugImage(const ImageView& image, const FaceTrack& track, const FaceSamples& samples,
                    const Intrinsics& intrinsics, std::vector<uint8_t>& out);

}  // namespace probeless::face_track
