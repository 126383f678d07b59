// The image-space depth merge of Gruber et al. 2015, §4, eq. 1-5: the raw sensor depth D_c and
// the volume's raycast D_v are fused into D' (selection by lambda_D and hole filling from the
// support regions Omega_I / Omega_D), smoothed into D'' (joint bilateral median guided by the
// intensity image) and denoised into D''' (small median).
//
// Windows: a "k x k" region around p is the (2 floor(k/2) + 1)^2 pixels at offsets
// -floor(k/2)..floor(k/2). Windows wider than 5 pixels are subsampled to 5 x 5 (offsets
// -2s, -s, 0, s, 2s with stride s = floor(k/4)), as the paper does for D''. Medians of an even
// count take the lower middle value (the floor((n-1)/2)-th smallest). Depths are metres, 0 =
// missing; intensities are 0..255 grey values.
#pragma once

#include "probeless/recon/math.h"
#include "probeless/recon/thread_pool.h"

namespace probeless::recon {

struct MergeOptions {
  int merge_k = 20;           // D' support region (paper: k = 20)
  float merge_lambda_i = 7;   // D' intensity threshold lambda_I, grey levels (paper: 7)
  float lambda_d_m = 0.05f;   // depth threshold lambda_D, metres (paper: 5 cm)
  int smooth_k = 8;           // D'' window (paper: k = 8, subsampled to 5 x 5)
  float smooth_lambda_i = 7;  // D'' intensity threshold (paper: 7)
  int denoise_k = 2;          // D''' window (paper: k = 2 -> 3 x 3, no intensity test)
  // Deviation from the paper (off = eq. 4 / 5 exactly): the D'' and D''' medians also gate by
  // depth (the centre's depth cluster, see MergeDepth), as a bilateral filter's range kernel
  // does, so that where the intensity cannot tell an object from its background (similar grey)
  // the median does not mix their depths.
  bool depth_gated_medians = true;
  // Optional deviation from the paper (off by default = eq. 3 exactly): D_v replaces a valid D_c
  // (|D_c - D_v| <= lambda_D) only where the support region agrees with the volume too
  // (|Omega_D| >= |Omega_I| / 2, the test eq. 3 applies to holes), so that a volume lagging an
  // object that moves less than lambda_D per frame replaces less of its measured depth. Costs a
  // D' window on every pixel (docs/recon.md: +2.5-3 ms CPU for a small gain).
  bool volume_needs_majority = false;
  // Deviation from the paper (0 = eq. 2 / 3 with the fixed lambda_D exactly): the agreement
  // threshold of eq. 2 and 3 at a pixel with measured depth z = D_c becomes
  //   lambda(z) = min(lambda_D, lambda_d_sigmas * sigma(z))          (see AgreementThreshold)
  // with sigma(z) the sensor's depth noise (below), so that a measurement more than
  // lambda_d_sigmas standard deviations from the volume is taken as measured: the volume there
  // lags a moving object (or is wrong), since a static surface's measurement scatters around the
  // volume's average by sigma. Near the camera sigma is millimetres (Kinect v1: 3.5 mm at 1.5 m)
  // while lambda_D = 5 cm; far away (sigma >= lambda_D / lambda_d_sigmas) the paper's lambda_D
  // applies. Default 3 (a static surface's measurement lies within 3 sigma of its true depth
  // 99.7 % of the time); docs/recon.md has the figures for 0 (the paper), 1-4.
  float lambda_d_sigmas = 3;
  // The sensor's axial depth noise, standard deviation in metres at depth z (metres):
  //   sigma(z) = sqrt(s(z)^2 + (q z^2)^2 / 12),  s(z) = a + b (z - z0)^2
  // (a = noise_a_m, b = noise_b_per_m, z0 = noise_z0_m, q = noise_quantisation_per_m).
  // s(z): the Kinect v1 axial noise model of Nguyen, Izadi and Lovell 2012 ("Modeling Kinect
  // sensor noise for improved 3D reconstruction and tracking", 3DIMPVT; fitted for surface angles
  // of 10-60 degrees: 0.0012 + 0.0019 (z - 0.4)^2 m); q z^2: the depth step of disparity
  // quantisation (Kinect v1 q ~ 0.00285 / m), a uniform error of variance step^2 / 12 (0 = not
  // modelled).
  float noise_a_m = 0.0012f;
  float noise_b_per_m = 0.0019f;
  float noise_z0_m = 0.4f;
  float noise_quantisation_per_m = 0;

  // Throws ReconError for k < 1 or a negative threshold or noise coefficient.
  void Validate() const;
};

// sigma(z) of MergeOptions (metres; z in metres, > 0).
float DepthNoiseSigma(float z, const MergeOptions& options);
// The depth agreement threshold of eq. 2 / 3 (metres) at measured depth z (metres):
// min(lambda_D, lambda_d_sigmas * DepthNoiseSigma(z)) when lambda_d_sigmas > 0 and z > 0, else
// lambda_D (the paper).
float AgreementThreshold(float z, const MergeOptions& options);

// The three passes' outputs (metres, 0 = missing), all the size of the inputs.
struct MergedDepth {
  DepthImage merged;    // D', eq. 3
  DepthImage smoothed;  // D'', eq. 4
  DepthImage denoised;  // D''', eq. 5 (the depth of G_r)
  // AgreementThreshold(D_c(p)) per pixel (metres) when lambda_d_sigmas > 0, else empty.
  DepthImage agreement;
};

// Runs eq. 1-5. `raw` = D_c, `volume` = D_v (same camera, same size), `intensity` = I_c
// registered to the depth. Throws ReconError if the sizes differ or an input is empty.
// Per pixel p of D' (eq. 3), with lambda(p) = AgreementThreshold(D_c(p)) (lambda_D in the paper):
//   D_c(p) valid, D_v(p) valid, |D_c - D_v| >  lambda(p) -> D_c(p)
//   D_c(p) valid, D_v(p) valid, |D_c - D_v| <= lambda(p) -> D_v(p) (with volume_needs_majority
//     only if |Omega_D| >= |Omega_I| / 2, else D_c(p))
//   D_c(p) valid, D_v(p) missing                        -> D_c(p)
//   D_c(p) missing, |Omega_D| >= |Omega_I| / 2 > 0 and D_v(p) valid -> D_v(p)
//   D_c(p) missing otherwise -> median{D_c(q) : q in Omega_I(p)} (0 if Omega_I is empty)
// with Omega_k(p) the valid D_c pixels of the window, Omega_I (eq. 1) those with
// |I(p) - I(q)| < lambda_I and Omega_D (eq. 2) those of Omega_I with a valid D_v and
// |D_c(q) - D_v(q)| < lambda(q). (The depth gate of the medians below uses lambda_D itself.)
// D''(p) (eq. 4) = median{D'(q) : q in Omega_I(p)} (window smooth_k, lambda_I smooth_lambda_i, on
// every pixel, 0 if empty); D'''(p) (eq. 5) = median of the valid D''(q) in the denoise_k window.
// With depth_gated_medians, where D_c(p) is valid and the centre value c = D'(p) (D''(p) for
// D''') is valid, the median takes only the samples of c's depth cluster -- those linked to c by
// steps < lambda_D between sample depths (the smallest interval [lo, hi] containing c with no
// sample in (lo - lambda_D, lo) or (hi, hi + lambda_D)) -- if they are at least a quarter of the
// samples; otherwise (D_c holes, isolated outliers) all samples as above. A quarter: a pixel at
// an object's convex 90-degree corner sees about a quarter of its window on the object.
void MergeDepth(const DepthImage& raw, const DepthImage& volume, const GreyImage& intensity,
                const MergeOptions& options, MergedDepth& out, ThreadPool* pool);

// Grey values (77 R + 150 G + 29 B) / 256 of an interleaved RGB image (3 bytes per pixel,
// `stride` bytes per row).
void GreyFromRgb(const uint8_t* rgb, int width, int height, size_t stride, GreyImage& out);

}  // namespace probeless::recon
