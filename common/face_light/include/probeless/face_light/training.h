// Offline training of the Knorr & Kurz (2014) radiance transfer functions (sec. 3.4, eq. 18) and
// sample point selection (sec. 6, "Improving the Offline Training Stage").
#pragma once

#include <array>
#include <functional>
#include <span>
#include <vector>

#include "probeless/face_light/model.h"

namespace probeless::face_light {

// Dense candidate grid inside the face mask, in normalised crop coordinates, row-major from the
// top-left: crop pixels (x, y) on a square grid of `step_px` pixels (offset so the grid is centred
// on the crop) that lie inside the face ellipse (centre (83.5, 100), semi-axes 80 x 96 px, and
// 8 <= y <= 183) and outside both eye regions (ellipses 24 x 17 px around kCanonical*Eye, moved
// 4 px up to cover the eyebrows) and the mouth (ellipse 26 x 9 px around kCanonicalMouth). The
// default step gives 512 candidates, the initial count of the paper. Throws FaceLightError unless
// 2 <= step_px <= 40.
std::vector<Point2> CandidatePositions(double step_px = 6.42);

// One training image reduced to its candidate samples.
struct TrainingImage {
  int subject = 0;         // person (Yale B subject number)
  double azimuth_deg = 0;  // light direction as in the Yale B file name
  double elevation_deg = 0;
  std::vector<float> values;   // sample intensity per candidate (e.g. from SamplePatches)
  std::vector<uint8_t> valid;  // 1 = use the value (same size as values)
};

struct TrainingOptions {
  // Keep the candidates whose |RTF coefficient| lies above this percentile (0..100) of all
  // candidates for at least one of the 9 SH coefficients (paper: 90 -> 294 of 512).
  double percentile = 90;
  // If > 0: keep exactly this many candidates instead, ranked by the same criterion (the highest
  // per-coefficient percentile rank); the percentile applied is stored in the model.
  int points = 0;
  int patch_radius_px = 2;  // stored in the model: the patch the values were sampled with
  // Response exponent (FaceLightModel::intensity_exponent), 0 < g <= 2; 1 = the paper.
  double intensity_exponent = 1;
  // Direction RTFs (FaceLightModel::direction_bands): 0 = none, 4 or 5 = also fit RTFs of that
  // many SH bands for the selected samples (FitDirectionRtfs), with a Tikhonov weight
  // direction_ridge relative to the mean diagonal of the normal matrix.
  int direction_bands = 0;
  double direction_ridge = 1e-3;
};

// Per-person albedo factor (sec. 3.4.2): the median of the subject's valid candidate values in
// its frontal-lit image (azimuth 0, elevation 0). Throws FaceLightError if the subject has no
// frontal-lit image or it has no valid value, or the median is not positive.
double PersonAlbedo(std::span<const TrainingImage> images, int subject);

// RTF fit (eq. 18) for every candidate: least squares over all images of all persons pooled, each
// intensity divided by its person's albedo and raised to intensity_exponent (1 = the paper),
// E_k = Y(direction of image k) (eq. 14, directional
// light of power 1). Pooling all persons into one system gives the average RTF in the
// least-squares sense (sec. 3.4). Returns per candidate the 9 coefficients and sets residual_rms
// (if not null) to the RMS residual. Throws FaceLightError if images disagree in candidate count
// or a candidate has fewer than 9 valid equations or a singular system.
std::vector<std::array<double, kRtfCoefficients>> FitRtfs(std::span<const TrainingImage> images,
                                                          std::vector<float>* residual_rms,
                                                          double intensity_exponent = 1);

// Like FitRtfs, but `bands` (1..5) SH bands and only for the candidates in `which`, with
// ridge * (mean diagonal) * I added to each normal matrix (the Yale B lights cover the sphere
// unevenly, so bands 3..4 are poorly determined behind the head). Returns
// which.size() * bands^2 coefficients, [k * bands^2 + n].
std::vector<double> FitDirectionRtfs(std::span<const TrainingImage> images,
                                     std::span<const int> which, int bands,
                                     double intensity_exponent, double ridge);

// Indices (ascending) of the candidates kept by the selection of TrainingOptions;
// *applied_percentile (if not null) receives the percentile in effect (for `points`, the lowest
// selected rank * 100).
std::vector<int> SelectSamples(std::span<const std::array<double, kRtfCoefficients>> rtfs,
                               const TrainingOptions& options, double* applied_percentile);

// The whole training: albedo normalisation, FitRtfs, SelectSamples, packed into a model whose
// training info lists the subjects of `images`. `progress` (may be empty) is called with values
// in [0, 1]. Throws FaceLightError (see above; also if more than 512 samples would be kept or
// options are out of range).
FaceLightModel Train(std::span<const Point2> candidates, std::span<const TrainingImage> images,
                     const TrainingOptions& options,
                     const std::function<void(double)>& progress = {});

}  // namespace probeless::face_light
