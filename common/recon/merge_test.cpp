// The depth merge (Gruber et al. 2015, eq. 1-5) on crafted inputs, one test per case of eq. 3,
// against hand-computed outputs.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "probeless/recon/depth_merge.h"
#include "probeless/simd/simd.h"

namespace probeless::recon {
namespace {

// 7 x 7 images, constant fill.
struct Inputs {
  DepthImage raw, volume;
  GreyImage grey;
  Inputs(float raw_value, float volume_value, uint8_t grey_value) {
    raw.Resize(7, 7);
    volume.Resize(7, 7);
    grey.Resize(7, 7);
    std::fill(raw.data.begin(), raw.data.end(), raw_value);
    std::fill(volume.data.begin(), volume.data.end(), volume_value);
    std::fill(grey.data.begin(), grey.data.end(), grey_value);
  }
};

// A 5 x 5 window without subsampling for D' (k = 4), so the support regions are easy to count,
// and the paper's fixed lambda_D in eq. 2 / 3 (the eq. 3 case tests are the paper's).
MergeOptions SmallWindows() {
  MergeOptions o;
  o.merge_k = 4;
  o.lambda_d_sigmas = 0;
  return o;
}

TEST(DepthMerge, Case1RawDiffersFromVolumeKeepsRaw) {
  Inputs in(1.00f, 1.00f, 100);
  in.raw.At(3, 3) = 1.20f;  // 20 cm > lambda_D from the volume's 1.00
  MergedDepth out;
  MergeDepth(in.raw, in.volume, in.grey, SmallWindows(), out, nullptr);
  EXPECT_FLOAT_EQ(out.merged.At(3, 3), 1.20f);
}

TEST(DepthMerge, Case2RawCloseToVolumeTakesVolume) {
  Inputs in(1.00f, 1.00f, 100);
  in.raw.At(3, 3) = 1.03f;  // 3 cm < lambda_D
  MergedDepth out;
  MergeDepth(in.raw, in.volume, in.grey, SmallWindows(), out, nullptr);
  EXPECT_FLOAT_EQ(out.merged.At(3, 3), 1.00f);
}

TEST(DepthMerge, Case3HoleWithMajorityAgreeingTakesVolume) {
  // Hole at (3, 3); its 5 x 5 window has 24 valid raw pixels. 12 agree with the volume (1.00),
  // 12 do not (1.50): |Omega_D| = 12 >= |Omega_I| / 2 = 12 -> D_v(p) = 0.90.
  Inputs in(1.00f, 1.00f, 100);
  int n = 0;
  for (int y = 1; y <= 5; ++y)
    for (int x = 1; x <= 5; ++x) {
      if (x == 3 && y == 3) continue;
      if (n++ % 2 == 0) in.raw.At(x, y) = 1.50f;
    }
  in.raw.At(3, 3) = 0;
  in.volume.At(3, 3) = 0.90f;
  MergedDepth out;
  MergeDepth(in.raw, in.volume, in.grey, SmallWindows(), out, nullptr);
  EXPECT_FLOAT_EQ(out.merged.At(3, 3), 0.90f);
}

TEST(DepthMerge, Case4HoleWithMinorityAgreeingTakesMedianOfOmegaI) {
  // Hole at (3, 3). Volume says 1.00 everywhere; raw window: 13 pixels at 1.50 (disagree), 11 at
  // 1.00 (agree) -> |Omega_D| = 11 < 12: median of the 24 raw values (lower middle = 1.50, the
  // 12th smallest of 11 x 1.00 and 13 x 1.50).
  Inputs in(1.00f, 1.00f, 100);
  int n = 0;
  for (int y = 1; y <= 5; ++y)
    for (int x = 1; x <= 5; ++x) {
      if (x == 3 && y == 3) continue;
      if (n++ < 13) in.raw.At(x, y) = 1.50f;
    }
  in.raw.At(3, 3) = 0;
  MergedDepth out;
  MergeDepth(in.raw, in.volume, in.grey, SmallWindows(), out, nullptr);
  EXPECT_FLOAT_EQ(out.merged.At(3, 3), 1.50f);
}

TEST(DepthMerge, IntensityThresholdRestrictsTheSupportRegion) {
  // Hole at (3, 3) with grey 100. Only the right two columns (x = 4, 5) have grey within
  // lambda_I (103); they hold 2.00 and disagree with the volume; the rest (grey 200) holds 1.00
  // and agrees. Omega_I = columns 4..5 of rows 1..5 (10 pixels), none in Omega_D -> median 2.00.
  Inputs in(1.00f, 1.00f, 200);
  in.grey.At(3, 3) = 100;
  for (int y = 0; y < 7; ++y)
    for (int x = 4; x < 7; ++x) {
      in.grey.At(x, y) = 103;
      in.raw.At(x, y) = 2.00f;
    }
  in.raw.At(3, 3) = 0;
  MergedDepth out;
  MergeDepth(in.raw, in.volume, in.grey, SmallWindows(), out, nullptr);
  EXPECT_FLOAT_EQ(out.merged.At(3, 3), 2.00f);
}

TEST(DepthMerge, HoleWithoutSupportStaysEmptyAndLaterPassesFillByMedian) {
  Inputs in(0.0f, 0.0f, 50);
  in.raw.At(0, 0) = 1.0f;
  MergeOptions o = SmallWindows();
  MergedDepth out;
  MergeDepth(in.raw, in.volume, in.grey, o, out, nullptr);
  // (6, 6) has no valid raw pixel within 2: stays a hole in D'.
  EXPECT_EQ(out.merged.At(6, 6), 0.0f);
  // (2, 2) has (0, 0) in its 5 x 5 window: median of {1.0}.
  EXPECT_FLOAT_EQ(out.merged.At(2, 2), 1.0f);
}

TEST(DepthMerge, SmoothingIsAJointBilateralMedianAndDenoisingASmallMedian) {
  // D'' (k = 8: offsets -4, -2, 0, 2, 4) on a step edge that follows the intensity edge:
  // left half grey 50 at 1.0 m, right half grey 150 at 2.0 m, one outlier 3.0 m on the left.
  DepthImage raw, volume;
  GreyImage grey;
  raw.Resize(11, 11);
  volume.Resize(11, 11);
  grey.Resize(11, 11);
  for (int y = 0; y < 11; ++y)
    for (int x = 0; x < 11; ++x) {
      grey.At(x, y) = x < 5 ? 50 : 150;
      raw.At(x, y) = x < 5 ? 1.0f : 2.0f;
    }
  raw.At(4, 5) = 3.0f;  // no volume: D' = D_c
  MergedDepth out;
  MergeDepth(raw, volume, grey, MergeOptions{}, out, nullptr);
  EXPECT_FLOAT_EQ(out.merged.At(4, 5), 3.0f);
  // The outlier is voted out by its own side only; edge pixels keep their side's depth.
  EXPECT_FLOAT_EQ(out.smoothed.At(4, 5), 1.0f);
  EXPECT_FLOAT_EQ(out.smoothed.At(5, 5), 2.0f);
  EXPECT_FLOAT_EQ(out.denoised.At(4, 5), 1.0f);
  // D''' is the 3 x 3 median: at the edge x = 4 the window holds 6 x 1.0 and 3 x 2.0 -> 1.0.
  EXPECT_FLOAT_EQ(out.denoised.At(4, 2), 1.0f);
  EXPECT_FLOAT_EQ(out.denoised.At(5, 2), 2.0f);
}

// A foreground object (1 m) over a background (2 m) of the same grey, so the intensity gate
// cannot separate them: the object's convex corner at (10, 10) sees 9 of its 25 D'' samples (and
// 4 of its 9 D''' samples) on the object. The depth gate keeps every pixel's depth, the corner's
// too; the paper's plain medians (eq. 4 / 5) hand the corner to the background's majority.
TEST(DepthMerge, DepthGateKeepsAnObjectsDepthAtItsSilhouette) {
  DepthImage raw, volume;
  GreyImage grey;
  raw.Resize(21, 21);
  volume.Resize(21, 21);
  grey.Resize(21, 21);
  std::fill(grey.data.begin(), grey.data.end(), 100);
  for (int y = 0; y < 21; ++y)
    for (int x = 0; x < 21; ++x) raw.At(x, y) = (x >= 10 && y >= 10) ? 1.0f : 2.0f;
  raw.At(15, 15) = 1.3f;  // an isolated outlier on the object: no support, voted out
  MergedDepth out;
  MergeDepth(raw, volume, grey, MergeOptions{}, out, nullptr);
  for (int y = 0; y < 21; ++y)
    for (int x = 0; x < 21; ++x) {
      const float want = (x >= 10 && y >= 10) ? 1.0f : 2.0f;
      EXPECT_FLOAT_EQ(out.smoothed.At(x, y), want) << x << "," << y;
      EXPECT_FLOAT_EQ(out.denoised.At(x, y), want) << x << "," << y;
    }
  MergeOptions paper;
  paper.depth_gated_medians = false;
  MergeDepth(raw, volume, grey, paper, out, nullptr);
  EXPECT_FLOAT_EQ(out.smoothed.At(10, 10), 2.0f);
  EXPECT_FLOAT_EQ(out.denoised.At(10, 10), 2.0f);
}

// Measured depth on a noisy surface (steps up to 4 cm, within lambda_D = 5 cm of each other but
// spanning 8 cm) is one cluster: the depth gate must not stop the median from denoising it.
TEST(DepthMerge, DepthGateStillDenoisesASurfaceNoisierThanLambdaD) {
  DepthImage raw, volume;
  GreyImage grey;
  raw.Resize(15, 15);
  volume.Resize(15, 15);
  grey.Resize(15, 15);
  std::fill(grey.data.begin(), grey.data.end(), 100);
  const float offsets[3] = {-0.04f, 0.0f, 0.04f};
  for (int y = 0; y < 15; ++y)
    for (int x = 0; x < 15; ++x) raw.At(x, y) = 3.0f + offsets[(x + y) % 3];
  MergedDepth gated, plain;
  MergeDepth(raw, volume, grey, MergeOptions{}, gated, nullptr);
  MergeOptions paper;
  paper.depth_gated_medians = false;
  MergeDepth(raw, volume, grey, paper, plain, nullptr);
  EXPECT_EQ(gated.smoothed.data, plain.smoothed.data);
  EXPECT_EQ(gated.denoised.data, plain.denoised.data);
  // (7, 7) = 3.04 is 4 cm off; its D'' window holds 8 or 9 samples of each level: median 3.00.
  EXPECT_FLOAT_EQ(raw.At(7, 7), 3.04f);
  EXPECT_FLOAT_EQ(gated.smoothed.At(7, 7), 3.0f);
}

// Noise-scaled agreement threshold (MergeOptions::lambda_d_sigmas, a deviation from eq. 2 / 3).
// Kinect v1 axial noise (Nguyen et al. 2012) at 1.5 m: 0.0012 + 0.0019 * 1.1^2 = 3.499 mm, so
// 3 sigma = 10.5 mm; at 4 m: 0.0012 + 0.0019 * 3.6^2 = 25.82 mm, 3 sigma = 77 mm > lambda_D.
MergeOptions NoiseScaled() {
  MergeOptions o = SmallWindows();
  o.lambda_d_sigmas = 3;
  return o;
}

TEST(DepthMerge, NoiseModelAndAgreementThresholdMatchHandComputedValues) {
  MergeOptions o = NoiseScaled();
  EXPECT_NEAR(DepthNoiseSigma(1.5f, o), 0.003499f, 1e-6f);
  EXPECT_NEAR(AgreementThreshold(1.5f, o), 0.010497f, 3e-6f);
  EXPECT_FLOAT_EQ(AgreementThreshold(4.0f, o), 0.05f);  // capped at lambda_D
  EXPECT_FLOAT_EQ(AgreementThreshold(0.0f, o), 0.05f);  // no measurement
  o.noise_quantisation_per_m = 0.00285f;                // step 11.4 mm at 2 m
  // sqrt(6.064^2 + 11.4^2 / 12) mm.
  EXPECT_NEAR(DepthNoiseSigma(2.0f, o), 0.0068994f, 2e-6f);
  EXPECT_FLOAT_EQ(AgreementThreshold(1.5f, SmallWindows()), 0.05f);  // off: the paper's lambda_D
  EXPECT_EQ(AgreementThreshold(1.5f, MergeOptions{}), AgreementThreshold(1.5f, NoiseScaled()));
}

TEST(DepthMerge, NoiseScaledMeasurementFourSigmaOffALaggingVolumeIsTakenRaw) {
  // The volume still shows an object 1.4 cm behind where it is measured now (4 sigma at 1.5 m,
  // within lambda_D): the paper takes D_v (case 2), the noise-scaled test keeps D_c.
  Inputs in(1.50f, 1.50f, 100);
  in.raw.At(3, 3) = 1.514f;
  MergedDepth out;
  MergeDepth(in.raw, in.volume, in.grey, NoiseScaled(), out, nullptr);
  EXPECT_FLOAT_EQ(out.merged.At(3, 3), 1.514f);
  MergeDepth(in.raw, in.volume, in.grey, SmallWindows(), out, nullptr);
  EXPECT_FLOAT_EQ(out.merged.At(3, 3), 1.50f);
}

TEST(DepthMerge, NoiseScaledStaticPixelWithinNoiseTakesVolume) {
  // 0.7 cm = 2 sigma at 1.5 m: a static surface's noise, the averaged volume depth replaces it.
  Inputs in(1.50f, 1.50f, 100);
  in.raw.At(3, 3) = 1.507f;
  MergedDepth out;
  MergeDepth(in.raw, in.volume, in.grey, NoiseScaled(), out, nullptr);
  EXPECT_FLOAT_EQ(out.merged.At(3, 3), 1.50f);
  EXPECT_EQ(out.agreement.At(3, 3), AgreementThreshold(1.507f, NoiseScaled()));
  // Far away the paper's lambda_D applies: 4 cm off at 4 m takes D_v, 6 cm off keeps D_c.
  Inputs far(4.00f, 4.00f, 100);
  far.raw.At(3, 3) = 4.04f;
  far.raw.At(4, 4) = 4.06f;
  MergeDepth(far.raw, far.volume, far.grey, NoiseScaled(), out, nullptr);
  EXPECT_FLOAT_EQ(out.merged.At(3, 3), 4.00f);
  EXPECT_FLOAT_EQ(out.merged.At(4, 4), 4.06f);
}

TEST(DepthMerge, NoiseScaledSupportRegionCountsOnlyPixelsWithinNoise) {
  // Hole at (3, 3) in an object measured 2 cm (~6 sigma) in front of the volume everywhere: with
  // lambda_D every neighbour is in Omega_D -> D_v(p); noise-scaled Omega_D is empty -> the median
  // of Omega_I (the measured 1.48).
  Inputs in(1.48f, 1.50f, 100);
  in.raw.At(3, 3) = 0;
  MergedDepth out;
  MergeDepth(in.raw, in.volume, in.grey, SmallWindows(), out, nullptr);
  EXPECT_FLOAT_EQ(out.merged.At(3, 3), 1.50f);
  MergeDepth(in.raw, in.volume, in.grey, NoiseScaled(), out, nullptr);
  EXPECT_FLOAT_EQ(out.merged.At(3, 3), 1.48f);
}

TEST(DepthMerge, RejectsBadNoiseModel) {
  Inputs in(1, 1, 1);
  MergedDepth out;
  MergeOptions o;
  o.lambda_d_sigmas = -1;
  EXPECT_THROW(MergeDepth(in.raw, in.volume, in.grey, o, out, nullptr), ReconError);
  o = MergeOptions{};
  o.noise_b_per_m = -0.001f;
  EXPECT_THROW(MergeDepth(in.raw, in.volume, in.grey, o, out, nullptr), ReconError);
}

TEST(DepthMerge, RejectsMismatchedSizes) {
  Inputs in(1, 1, 1);
  DepthImage small;
  small.Resize(3, 3);
  MergedDepth out;
  EXPECT_THROW(
      {
        try {
          MergeDepth(in.raw, small, in.grey, MergeOptions{}, out, nullptr);
        } catch (const ReconError& e) {
          EXPECT_STREQ(e.what(),
                       "merge: raw depth 7x7, volume depth 3x3 and intensity 7x7 must have the "
                       "same size");
          throw;
        }
      },
      ReconError);
  DepthImage empty;
  EXPECT_THROW(MergeDepth(empty, empty, in.grey, MergeOptions{}, out, nullptr), ReconError);
}

}  // namespace
}  // namespace probeless::recon

namespace probeless::recon {
namespace {

// Straightforward eq. 1-5 (as documented in depth_merge.h) for the vectorised implementation to
// match exactly on random inputs (holes, edges, borders).
float RefMedian(std::vector<float> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[(v.size() - 1) / 2];
}
struct Win {
  int half, stride;
};
// The depth gate of D'' / D''' (depth_merge.h): the samples linked to the valid centre by depth
// steps < lambda_D (walking the sorted samples outwards from the centre) when they are at least
// a quarter of all, else all.
std::vector<float> RefGate(std::vector<float> s, float centre, const MergeOptions& o) {
  if (!o.depth_gated_medians || !(centre > 0)) return s;
  std::sort(s.begin(), s.end());
  float lo = centre, hi = centre;
  for (auto it = std::lower_bound(s.begin(), s.end(), centre); it != s.end(); ++it) {
    if (!(*it < hi + o.lambda_d_m)) break;
    hi = std::max(hi, *it);
  }
  for (auto it = std::upper_bound(s.begin(), s.end(), centre); it != s.begin();) {
    --it;
    if (!(*it > lo - o.lambda_d_m)) break;
    lo = std::min(lo, *it);
  }
  std::vector<float> cluster;
  for (float d : s)
    if (d >= lo && d <= hi) cluster.push_back(d);
  return 4 * cluster.size() >= s.size() ? cluster : s;
}
Win RefWindow(int k) {
  const int half = k / 2;
  if (half <= 2) return {half, 1};
  const int s = std::max(1, half / 2);
  return {2 * s, s};
}
MergedDepth Reference(const DepthImage& raw, const DepthImage& vol, const GreyImage& grey,
                      const MergeOptions& o) {
  const int w = raw.width, h = raw.height;
  MergedDepth out;
  out.merged.Resize(w, h);
  out.smoothed.Resize(w, h);
  out.denoised.Resize(w, h);
  auto window = [&](int x, int y, Win win, auto&& fn) {
    for (int dy = -win.half; dy <= win.half; dy += win.stride)
      for (int dx = -win.half; dx <= win.half; dx += win.stride) {
        const int xx = x + dx, yy = y + dy;
        if (xx >= 0 && yy >= 0 && xx < w && yy < h) fn(xx, yy);
      }
  };
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float dc = raw.At(x, y), dv = vol.At(x, y);
      const bool agrees = dv > 0 && std::fabs(dc - dv) <= AgreementThreshold(dc, o);
      if (dc > 0 && !(agrees && o.volume_needs_majority)) {
        out.merged.At(x, y) = agrees ? dv : dc;
        continue;
      }
      std::vector<float> omega_i;
      int omega_d = 0;
      window(x, y, RefWindow(o.merge_k), [&](int xx, int yy) {
        const float dq = raw.At(xx, yy);
        if (dq > 0 && std::abs(grey.At(x, y) - grey.At(xx, yy)) < o.merge_lambda_i) {
          omega_i.push_back(dq);
          if (vol.At(xx, yy) > 0 && std::fabs(dq - vol.At(xx, yy)) < AgreementThreshold(dq, o)) {
            ++omega_d;
          }
        }
      });
      if (dc > 0) {
        out.merged.At(x, y) = 2 * omega_d >= static_cast<int>(omega_i.size()) ? dv : dc;
        continue;
      }
      out.merged.At(x, y) = omega_i.empty() ? 0
                            : (dv > 0 && 2 * omega_d >= static_cast<int>(omega_i.size()))
                                ? dv
                                : RefMedian(omega_i);
    }
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      std::vector<float> s;
      window(x, y, RefWindow(o.smooth_k), [&](int xx, int yy) {
        const float d = out.merged.At(xx, yy);
        if (d > 0 && std::abs(grey.At(x, y) - grey.At(xx, yy)) < o.smooth_lambda_i) s.push_back(d);
      });
      out.smoothed.At(x, y) = RefMedian(RefGate(s, raw.At(x, y) > 0 ? out.merged.At(x, y) : 0, o));
    }
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      std::vector<float> s;
      window(x, y, RefWindow(o.denoise_k), [&](int xx, int yy) {
        if (out.smoothed.At(xx, yy) > 0) s.push_back(out.smoothed.At(xx, yy));
      });
      out.denoised.At(x, y) =
          RefMedian(RefGate(s, raw.At(x, y) > 0 ? out.smoothed.At(x, y) : 0, o));
    }
  return out;
}

TEST(DepthMerge, MatchesTheStraightforwardEquationsOnRandomInputs) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> depth(0.5f, 0.8f);
  std::uniform_int_distribution<int> grey(90, 110);
  std::uniform_int_distribution<int> pct(0, 99);
  // Few and many holes: every sample count 0..25 of the vectorised medians occurs.
  for (const int holes_pct : {25, 85}) {
    DepthImage raw, vol;
    GreyImage g;
    raw.Resize(77, 41);
    vol.Resize(77, 41);
    g.Resize(77, 41);
    for (size_t i = 0; i < raw.data.size(); ++i) {
      raw.data[i] = pct(rng) < holes_pct ? 0.0f : depth(rng);
      vol.data[i] =
          pct(rng) < holes_pct / 2 ? 0.0f : (pct(rng) < 50 ? raw.data[i] + 0.01f : depth(rng));
      g.data[i] = static_cast<uint8_t>(grey(rng));
    }
    // lambda_D = 1 cm splits the random depths into many clusters (the gate's both branches).
    MergeOptions fine, fine_small = SmallWindows();
    fine.lambda_d_m = fine_small.lambda_d_m = 0.01f;
    fine.volume_needs_majority = fine_small.volume_needs_majority = true;
    fine.lambda_d_sigmas = fine_small.lambda_d_sigmas = 0;
    MergeOptions paper_exact, paper_exact_small = SmallWindows();
    paper_exact.depth_gated_medians = paper_exact_small.depth_gated_medians = false;
    paper_exact.volume_needs_majority = paper_exact_small.volume_needs_majority = false;
    paper_exact.lambda_d_sigmas = paper_exact_small.lambda_d_sigmas = 0;
    // Noise-scaled agreement: 8 sigma is 0.98-1.20 cm over these depths, so the +1 cm volume
    // pixels agree at some depths and not at others.
    MergeOptions noisy, noisy_small = SmallWindows();
    noisy.lambda_d_sigmas = noisy_small.lambda_d_sigmas = 8;
    noisy_small.volume_needs_majority = true;
    noisy_small.noise_quantisation_per_m = 0.00285f;
    for (MergeOptions o : {MergeOptions{}, SmallWindows(), fine, fine_small, paper_exact,
                           paper_exact_small, noisy, noisy_small}) {
      ThreadPool pool(2);
      MergedDepth got;
      MergeDepth(raw, vol, g, o, got, &pool);
      const MergedDepth want = Reference(raw, vol, g, o);
      EXPECT_EQ(got.merged.data, want.merged.data);
      EXPECT_EQ(got.smoothed.data, want.smoothed.data);
      EXPECT_EQ(got.denoised.data, want.denoised.data);
    }
  }
}

}  // namespace
}  // namespace probeless::recon

namespace probeless::recon {
namespace {

// The portable and the AVX2/FMA kernels (chosen at run time, probeless/simd/simd.h) on a noisy
// 160x120 scene with holes, both noise models. Every output is one of the input depths (medians
// select), so the two agree exactly except where FMA rounding flips the noise-scaled agreement
// test of a pixel: at most 0.1 % of the pixels.
TEST(DepthMerge, PortableAndAvx2KernelsAgree) {
  if (simd::Supported() != simd::Level::kAvx2Fma) GTEST_SKIP() << "no AVX2/FMA on this CPU";
  constexpr int kW = 160, kH = 120;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  DepthImage raw, volume;
  GreyImage grey;
  raw.Resize(kW, kH), volume.Resize(kW, kH), grey.Resize(kW, kH);
  for (int y = 0; y < kH; ++y) {
    for (int x = 0; x < kW; ++x) {
      const float z = 1.0f + 0.5f * std::sin(0.05f * x) + (x > 60 && x < 100 ? -0.3f : 0.0f);
      raw.At(x, y) = uni(rng) < 0.15f ? 0.0f : z + 0.01f * (uni(rng) - 0.5f);
      volume.At(x, y) = uni(rng) < 0.05f ? 0.0f : z + 0.02f * (uni(rng) - 0.5f);
      grey.At(x, y) = static_cast<uint8_t>(x > 60 && x < 100 ? 200 : 60 + 20 * uni(rng));
    }
  }
  for (float sigmas : {0.0f, 3.0f}) {
    MergeOptions o;
    o.lambda_d_sigmas = sigmas;
    MergedDepth a, b;
    {
      simd::ScopedLevel portable(simd::Level::kPortable);
      MergeDepth(raw, volume, grey, o, a, nullptr);
    }
    {
      simd::ScopedLevel avx2(simd::Level::kAvx2Fma);
      MergeDepth(raw, volume, grey, o, b, nullptr);
    }
    int differ = 0;
    for (size_t i = 0; i < a.denoised.data.size(); ++i) {
      differ += a.merged.data[i] != b.merged.data[i] || a.smoothed.data[i] != b.smoothed.data[i] ||
                a.denoised.data[i] != b.denoised.data[i];
    }
    EXPECT_LE(differ, kW * kH / 1000) << "lambda_d_sigmas " << sigmas;
  }
}

}  // namespace
}  // namespace probeless::recon
