// Knorr & Kurz (2014) face light model: the canonical face frame, the trained radiance transfer
// functions (RTFs) of the sample positions, patch sampling and the model file (docs/face_light.md).
//
// Canonical face frame: the aligned, cropped Extended Yale B image (168 x 192 pixels, frontal pose,
// the subject looking into the camera). Crop pixel (x, y): x right, y down, (0, 0) = centre of the
// top-left pixel. Sample positions are stored in normalised crop coordinates
// (u, v) = ((x + 0.5) / 168, (y + 0.5) / 192), so (0, 0) is the crop's top-left corner and (1, 1)
// its bottom-right corner. The crop alignment puts the face landmarks at the kCanonical* points
// below (measured on the mean of the 27 frontal-lit crops, +-2 px); a tracker maps live landmarks
// to this frame with a similarity transform (FitSimilarity) and samples the same positions.
//
// Light frame: the face frame of msgs::FaceObservation for a frontal face (x towards the subject's
// left ear = image right, y towards the chin = image down, z into the head), i.e. the camera frame
// of the training images. Light directions point from the face towards the light.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/error/error.h"

namespace probeless::face_light {

// Bad input at the library's boundary (malformed or mismatched model file, bad sample counts,
// unreadable data set): one line naming the thing and what was expected.
class FaceLightError : public InputError {
 public:
  using InputError::InputError;
};

// Size of the canonical crop in pixels.
inline constexpr int kCropWidth = 168;
inline constexpr int kCropHeight = 192;
// RTF and light coefficients: SH bands 0..2 (Knorr & Kurz eq. 12-13, L = 2).
inline constexpr int kShBands = 3;
inline constexpr int kRtfCoefficients = 9;
// Most samples a model may hold (= msgs::kMaxFaceSamples, so a FaceObservation can carry them).
inline constexpr int kMaxSamples = 512;

// A 2-D point in pixels (or normalised coordinates where stated).
struct Point2 {
  double x = 0;
  double y = 0;
};

// Landmarks of the canonical crop, in crop pixels (mean of the 27 frontal-lit Yale B crops).
// "Right eye" is the subject's right eye (image left).
inline constexpr Point2 kCanonicalRightEye{32, 44};
inline constexpr Point2 kCanonicalLeftEye{133, 44};
inline constexpr Point2 kCanonicalNoseTip{83, 95};
inline constexpr Point2 kCanonicalMouth{83, 147};

// Normalised crop coordinates (u, v) -> crop pixel (u * 168 - 0.5, v * 192 - 0.5), and back.
Point2 CropPixelFromNormalised(Point2 uv);
Point2 NormalisedFromCropPixel(Point2 pixel);

// Similarity transform p -> (a x - b y + tx, b x + a y + ty): rotation, uniform scale
// sqrt(a^2 + b^2) and translation, e.g. from canonical crop pixels to live image pixels.
struct SimilarityTransform {
  double a = 1, b = 0, tx = 0, ty = 0;
  Point2 Apply(Point2 p) const { return {a * p.x - b * p.y + tx, b * p.x + a * p.y + ty}; }
  double Scale() const;
};

// Least-squares similarity transform mapping `from` onto `to` (same order, e.g. the kCanonical*
// landmarks onto tracked ones). Throws FaceLightError unless both hold the same number >= 2 of
// points and `from` is not degenerate (all points equal).
SimilarityTransform FitSimilarity(std::span<const Point2> from, std::span<const Point2> to);

// Samples the box patch of (2 r' + 1)^2 pixels around each position, r' = round(patch_radius_px *
// crop_to_image.Scale()), centred on the pixel nearest to crop_to_image(CropPixelFromNormalised(
// position)). image: 8-bit, `channels` (1..3) interleaved values per pixel, row y at y * stride
// bytes. values[i * channels + c] = mean of channel c / 255 (so in [0, 1]); valid[i] = 1 unless
// the patch leaves the image or one of its values reaches saturation (>= saturation_level,
// 0..255; 256 disables the check), in which case values are still written (the clipped mean, or
// 0 if nothing is inside) and valid[i] = 0. Throws FaceLightError on inconsistent sizes.
void SamplePatches(const uint8_t* image, int width, int height, size_t stride, int channels,
                   const SimilarityTransform& crop_to_image, std::span<const Point2> positions,
                   int patch_radius_px, int saturation_level, std::span<float> values,
                   std::span<uint8_t> valid);

// How a model was trained (stored in the model file; date-free so training is reproducible
// byte for byte).
struct TrainingInfo {
  std::vector<int> subjects;  // Yale B subject numbers used for training, ascending
  int images = 0;             // training images (light images; ambient images are excluded)
  int candidates = 0;         // candidate positions the samples were selected from
  double percentile = 90;     // selection percentile actually applied (Knorr & Kurz sec. 6), 0..100
  std::string albedo = "median-frontal-candidates";  // per-person albedo normalisation rule
};

// A trained model: sample positions and their RTFs.
struct FaceLightModel {
  // 2 adds direction_bands and the direction RTFs; version-1 files still load (no direction RTFs).
  static constexpr int kFormatVersion = 2;
  static constexpr std::string_view kMagic = "probeless_face_light_model";

  // Sample i: position in normalised crop coordinates.
  std::vector<Point2> positions;
  // Sample i's RTF: 9 SH coefficients (bands 0..2, probeless::sh convention) such that the
  // albedo-normalised intensity under incident light E is rtf[i] . E (Knorr & Kurz eq. 17).
  std::vector<std::array<float, kRtfCoefficients>> rtf;
  // Sample i's RMS residual of the training fit (eq. 18), albedo-normalised intensity units.
  std::vector<float> residual_rms;
  // Half size of the box patch in canonical crop pixels: (2 r + 1)^2 pixels.
  int patch_radius_px = 2;
  // Response exponent g: RTFs relate I^g (sample intensity raised to g, after albedo
  // normalisation) to the light, and the estimator raises its inputs to g. 1 = the paper (linear
  // radiance); 0.5 compresses highlights and is more accurate on Yale B (docs/face_light.md), but
  // the light is then in "compressed" units: its direction is meaningful, its scale and colour
  // ratios are those of I^g.
  double intensity_exponent = 1;
  TrainingInfo training;
  // Optional direction RTFs (format version 2): per sample, direction_bands^2 SH coefficients
  // (bands 0..direction_bands-1, same convention) fitted like `rtf` (same albedo normalisation and
  // exponent) but with more bands, so they follow the sharp attached shadows of a directional
  // light better. Used only by the estimator's directional fit. 0 = none; else 4 or 5.
  int direction_bands = 0;
  std::vector<float> direction_rtf;  // [i * direction_bands^2 + n]

  int SampleCount() const { return static_cast<int>(positions.size()); }
  // Throws FaceLightError unless 1..512 samples with matching rtf / residual_rms sizes, finite
  // values, positions inside [0, 1]^2, 0 <= patch_radius_px <= 16, 0 < intensity_exponent <= 2 and
  // direction_bands 0, 4 or 5 with SampleCount() * direction_bands^2 finite direction_rtf values.
  void Validate() const;
};

// The model as the text of a version-2 model file (docs/face_light.md). Deterministic: the same
// model gives the same bytes; floats are written with 9 significant digits (exact round trip).
std::string SerializeModel(const FaceLightModel& model);
// Parses a model file's text; `name` (e.g. the path) prefixes error messages. Throws
// FaceLightError "<name>: line <n>: <problem>" for a bad magic, an unsupported version, a
// different SH convention, missing or malformed fields, truncation or invalid values.
FaceLightModel ParseModel(std::string_view text, std::string_view name);
// File variants of the above. Throw FaceLightError "<path>: ..." also when the file cannot be
// opened, read or written.
void SaveModel(const FaceLightModel& model, const std::string& path);
FaceLightModel LoadModel(const std::string& path);

}  // namespace probeless::face_light
