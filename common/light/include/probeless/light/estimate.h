// Light estimation from radiance transfer (Gruber et al. 2015, §5.2): the white SH light l that
// solves T l = I_c / albedo in the least-squares sense over the valid pixels, optionally robust
// (IRLS: Huber, then Tukey's biweight) and non-negative, plus the dominant direction from the
// linear band (Sloan's optimal linear direction, probeless/sh/sh.h).
#pragma once

#include <span>
#include <vector>

#include "probeless/light/directions.h"
#include "probeless/light/transfer.h"

namespace probeless::light {

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
  bool robust = true;         // IRLS: 2 Huber then 3 Tukey iterations, MAD scale
  bool non_negative = false;  // penalise negative radiance at 64 Fibonacci directions
  int min_pixels = 32;        // fewer usable pixels -> invalid estimate
  // Balances normal orientations: every row is weighted by 1 / (rows in its orientation bin),
  // orientation = the direction of T's band-1 part (proportional to the normal for unoccluded
  // pixels), bins = the 96 cells of a 6 x 4 x 4 cube map. Without it the large planes of a room
  // (floor, walls) dominate the fit and the few pixels with other normals that pin the direction
  // down are drowned or rejected as outliers.
  bool balance_normals = true;
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
LightEstimate EstimateLight(const TransferResult& transfer, std::span<const float> intensity,
                            const EstimateOptions& options);

// The solver itself: rows (m x coefficient_count, row-major) and targets (m) already divided by
// the albedo. Throws LightError for sizes that do not match or coefficient_count not in
// {4, 9, 16, 25}.
LightEstimate SolveLight(std::span<const float> rows, std::span<const float> targets,
                         int coefficient_count, const EstimateOptions& options);

}  // namespace probeless::light
