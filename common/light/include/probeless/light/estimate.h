// Light estimation from radiance transfer (Gruber et al. 2015, §5.2): the white SH light l that
// solves T l = I_c / albedo in the least-squares sense over the valid pixels, optionally robust
// (IRLS: Huber, then Tukey's biweight) and non-negative, plus the dominant direction from the
// linear band (Sloan's optimal linear direction, probeless/sh/sh.h).
#pragma once

#include <array>
#include <deque>
#include <span>
#include <vector>

#include "probeless/light/directions.h"
#include "probeless/light/transfer.h"

namespace probeless::light {

// A prior on the light's shape (beyond the paper): indoors and outdoors light arrives mostly from
// above (sky, ceiling lamps, lit ceilings) and the image alone cannot separate a surface's albedo
// from its shading (the albedo groups free one albedo per colour), so the fit is pulled towards
// a light that is rotationally symmetric about `up` with the band ratios `zonal`. It enters as
// rows sqrt(w) (l_k - rho_k l_0) = 0 for every coefficient k >= 1, rho_k = (zonal[l] / (2l + 1))
// Y_k(up) / Y_00 (the zonal function sum_l zonal[l] P_l(up . d) times the light's own band 0), so
// the light's level stays the data's; its weight grows with what the fit leaves unexplained.
// Defaults chosen on the evaluation world's train split (docs/light.md, "Light prior").
struct LightPrior {
  // Weight relative to trace(T^T T) / coefficient count (as EstimateOptions::ridge) per unit of
  // (1 - R^2) / R^2, the share of the targets' variance the fit leaves unexplained (R^2 clamped to
  // >= 0.05; updated with every reweighting): data the model explains keeps its light; 0 = off.
  double weight = 0;
  // Unit up direction in the frame of T (the camera frame); (0, 0, 0) = no prior this frame.
  Vec3f up{0, 0, 0};
  // Zonal Legendre coefficients z_l / z_0 of the prior light, bands 0..3 (zonal[0] = 1).
  std::array<float, 4> zonal{1, 0, 0, 0};
};

struct EstimateOptions {
  int stride = 4;                // every stride-th pixel in x and y enters the system (>= 1)
  float albedo = 0.6f;           // assumed uniform grey albedo A(x) (the paper's white-light model)
  float min_intensity = 0.004f;  // pixels darker (noise floor) or
  float max_intensity = 0.98f;   // brighter (saturated) than this are left out (linear grey)
  // Tikhonov weight relative to trace(T^T T) / coefficient count. Keep it tiny: band 3 of a
  // clamped cosine vanishes (A_3 = 0), and a larger uniform ridge leaks into band 1 (measured:
  // 1e-3 turns the dominant direction by 12 degrees on exact data).
  double ridge = 1e-6;
  // Smoothness prior: adds smoothness * trace(T^T T) / coefficient count * (l (l + 1))^2 to the
  // diagonal entry of every degree-l coefficient (a squared spherical-Laplacian penalty). Band 0
  // is free, band 1 nearly so; it keeps bands 2-3 from absorbing what a scene with few normal
  // orientations cannot tell apart (a floor and a wall say little about band 2).
  double smoothness = 1e-3;
  bool robust = true;  // IRLS: huber_iterations, then tukey_iterations reweighted solves, MAD scale
  int huber_iterations = 2;   // Huber (k = 1.345) reweightings (convex; a reliable start)
  int tukey_iterations = 3;   // Tukey biweight (c = 4.685) reweightings (rejects gross outliers)
  bool non_negative = false;  // penalise negative radiance at 64 Fibonacci directions
  int min_pixels = 32;        // fewer usable pixels -> invalid estimate
  // Balances normal orientations: every row is weighted by 1 / (rows in its orientation bin),
  // orientation = the direction of T's band-1 part (proportional to the normal for unoccluded
  // pixels), bins = the 96 cells of a 6 x 4 x 4 cube map. Without it the large planes of a room
  // (floor, walls) dominate the fit and the few pixels with other normals that pin the direction
  // down are drowned or rejected as outliers.
  bool balance_normals = true;
  // With balance_normals: an orientation bin with more rows than this keeps every k-th of them
  // (0 = all). The bin's total weight is unchanged; the big planes of a room lose most of their
  // rows, the rare orientations keep all of theirs — the solve's cost drops with little effect
  // on the result (docs/light.md).
  int max_rows_per_bin = 100;
  // SH bands of the estimated light (2..bands of the transfer; 0 = all bands of the transfer):
  // the first bands^2 columns of T enter the system.
  int bands = 0;
  // The dominant direction and intensity come from a second fit of bands 0..direction_bands-1
  // (same rows and options; 0 or >= the full fit's bands = from the full fit): with N = 32
  // directions the band-3 columns of T are mostly quadrature noise (the clamped cosine has
  // A_3 = 0) and soak up part of the linear band; bands 0-1 alone cannot model the clamping
  // max(0, n.d) and bias the direction. Measured in docs/light.md.
  int direction_bands = 2;
  // Refit the direction twice on the pixels facing it (see estimate.cpp): a linear model is exact
  // there, while the pixels in attached shadow bias it.
  bool lit_refits = true;
  // Per-group albedo from the colour image (EstimateLight): chromaticity cells per axis
  // (0 = off: one uniform albedo) and light <-> albedo alternations (>= 1; the direction fits
  // run in the last one only).
  int albedo_groups = 32;
  int albedo_iterations = 3;
  // Group by the illuminant-invariant log-chromaticity coordinate instead of the chromaticity
  // cells (Finlayson, Drew & Lu 2004; light's albedo_groups.h): a light whose colour varies over
  // the surfaces (a warm lamp against a bluish ambient) splits one material over several
  // chromaticity cells by its shading; the invariant coordinate does not (docs/light.md).
  bool albedo_invariant = false;
  // The shape prior (LightPrior; off by default here, set by the scene pipeline per frame).
  LightPrior prior;
};

struct LightEstimate {
  bool valid = false;  // false: too few usable pixels
  int bands = 0;
  std::vector<double> coefficients;   // bands^2, white light in the frame of T (camera frame)
  Vec3f dominant_direction{0, 0, 0};  // unit, towards the light; (0, 0, 0) if band 1 vanishes
  float intensity = 0;                // sh::DirectionalPower along dominant_direction
  float confidence = 0;               // [0, 1]: weighted R^2 of the fit x pixel-count saturation
  int pixels = 0;                     // rows used
  double rms_residual = 0;            // weighted RMS of T l - I / albedo
};

// Estimates from a transfer buffer and the linear grey image (width * height values, e.g. from
// SrgbToLinearGrey). Throws LightError if the sizes differ from `transfer` or options are invalid.
//
// `colour` (optional, 3 sRGB bytes per pixel, the camera image; empty = one uniform albedo, the
// paper's grey world): with options.albedo_groups > 0 the rows are grouped by the chromaticity
// (r, g) = (R, G) / (R + G + B) of their linear colour (a albedo_groups x albedo_groups grid:
// under white light a material's chromaticity is its albedo's) and each group gets its own
// unknown albedo. The fit alternates (options.albedo_iterations times) between the light
// (targets I / a_g) and the albedos a_g = sum(I p) / sum(p^2), p = T l over the group's rows
// (groups of fewer than 16 rows keep the mean), normalised to a row-weighted mean of
// options.albedo. Only the shading variation inside a group and between groups of the same
// colour then carries direction information, so an object whose albedo differs from the assumed
// one (a skin-coloured head, a red ball) no longer biases the light (docs/light.md).
//
// `reliability` (optional, width * height values in [0, 1], e.g. NormalReliability): the weight
// of each pixel's row; pixels <= 0 are left out. With balance_normals an orientation bin's total
// weight is the mean reliability of its rows, so that unreliable normals (depth edges, creases)
// are not balanced up to a full bin (docs/light.md, "Normal reliability").
LightEstimate EstimateLight(const TransferResult& transfer, std::span<const float> intensity,
                            const EstimateOptions& options, std::span<const uint8_t> colour = {},
                            std::span<const float> reliability = {});

// The solver itself: rows (m x coefficient_count, row-major) and targets (m) already divided by
// the albedo; row_weights (optional, m values >= 0) weight the rows as EstimateLight's
// reliability. Throws LightError for sizes that do not match or coefficient_count not in
// {4, 9, 16, 25}.
LightEstimate SolveLight(std::span<const float> rows, std::span<const float> targets,
                         int coefficient_count, const EstimateOptions& options,
                         std::span<const float> row_weights = {});

// The real-SH rotation matrix of `bands` bands (row-major bands^2 x bands^2) for the direction
// rotation `rotation` (row-major 3 x 3, d' = R d): A[k][n] = integral Y_k(d) Y_n(R d) dw, so that
// light coefficients l' of a function in the rotated frame give l = A l' in the original one
// (exact up to rounding: Gauss-Legendre quadrature). Throws LightError unless 1 <= bands <= 5.
void ShRotationMatrix(const float rotation[9], int bands, std::vector<double>* out);

struct TemporalOptions {
  // Frames whose rows are solved together (the current one included; 1 = EstimateLight).
  int frames = 1;
  // Weight of a frame's rows relative to the next newer frame's, in [0, 1]: the frame k frames
  // back weighs forgetting^k.
  float forgetting = 0.5f;
  // The history is dropped when the current frame's RMS residual under the last estimate
  // exceeds reset_ratio x the last frame's own (the light switched or moved; 0 = never).
  float reset_ratio = 1.3f;
};

// Temporal accumulation (beyond the paper): the fit of EstimateLight over the rows of the last
// `frames` frames, older ones weighted by forgetting^age and rotated into the current camera
// frame, so that per-frame noise averages out; a light that switches or jumps resets the history
// (TemporalOptions::reset_ratio) and is followed at once. Not thread-safe; one per stream.
class TemporalLightEstimator {
 public:
  // Throws LightError for frames < 1 or forgetting outside [0, 1].
  explicit TemporalLightEstimator(const TemporalOptions& options = {});

  // As EstimateLight for the current frame. `rotation` (row-major 3 x 3, optional): the
  // camera's rotation from the previous call's camera frame into this one's (d_now = R d_prev;
  // nullptr = the camera did not rotate); `reliability` as EstimateLight's. Throws LightError
  // as EstimateLight (prefix "light::TemporalLightEstimator::Estimate").
  LightEstimate Estimate(const TransferResult& transfer, std::span<const float> intensity,
                         const EstimateOptions& options, std::span<const uint8_t> colour = {},
                         const float* rotation = nullptr, std::span<const float> reliability = {});
  // Forgets the history (e.g. after a tracking loss or a cut).
  void Reset();
  const TemporalOptions& options() const { return options_; }

 private:
  struct Frame {
    int coefficient_count = 0;
    std::vector<float> rows, targets, rgb;  // rows in the latest camera frame, pre-weighted
    std::vector<float> weights;             // reliability per row (empty: none)
  };
  TemporalOptions options_;
  std::deque<Frame> history_;  // newest first
  std::vector<double> rotation_sh_;
  std::vector<double> last_light_;  // the last estimate, current camera frame
  double last_rms_ = 0;             // the last frame's RMS residual under it
};

}  // namespace probeless::light
