// face_light_bench: nanoseconds per light estimate for a model (default: the shipped model) over
// deterministic synthetic frames (fixed seed), per estimator mode; median of repeated batches.
//
//   face_light_bench [--model MODEL] [--frames N] [--json FILE] [--case NAME]
#include "probeless/node/main.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "probeless/face_light/estimator.h"
#include "probeless/face_light/model.h"
#include "probeless/node/flags.h"

namespace fl = probeless::face_light;

namespace {

struct Case {
  std::string name;
  fl::EstimatorOptions options;
  bool rgb = false;
  int invalid_every = 0;  // every k-th sample invalid (0 = all valid)
  // true: every frame of a batch has its own validity mask with ~1/invalid_every of the samples
  // invalid at random (fixed seed), so no per-mask cache hits; false: one steady mask.
  bool changing_mask = false;
};

int Run(int argc, char** argv) {
  std::string model_path = std::string(PROBELESS_DEFAULT_MODEL);
  std::string json_path;
  std::string only_case;
  int frames = 2000;
  probeless::node::FlagParser flags(
      "face_light_bench",
      "nanoseconds per light estimate for a model over deterministic synthetic frames (fixed\n"
      "seed), per estimator mode; median of repeated batches");
  flags.Add("--model", &model_path, "MODEL", "the face light model");
  flags.Add("--frames", &frames, "N", "estimates timed per mode (batches of 64)", 1);
  flags.Add("--json", &json_path, "FILE", "also write the figures as JSON");
  flags.Add("--case", &only_case, "NAME", "only this estimator mode");
  if (!flags.Parse(argc, argv)) return 0;
  const fl::FaceLightModel model = fl::LoadModel(model_path);
  const int n = model.SampleCount();
  // Synthetic frames: a random light rendered through the RTFs plus noise, as linear intensities.
  std::mt19937_64 rng(12345);
  const auto uniform = [&]() { return static_cast<double>(rng() >> 11) * 0x1.0p-53; };
  std::vector<std::vector<float>> rgb_frames(64, std::vector<float>(3 * n));
  for (auto& frame : rgb_frames) {
    double light[3][9];
    for (auto& channel : light) {
      for (double& c : channel) c = uniform() - 0.5;
      channel[0] += 1.5;
    }
    for (int i = 0; i < n; ++i) {
      for (int c = 0; c < 3; ++c) {
        double value = 0;
        for (int k = 0; k < 9; ++k) value += model.rtf[i][k] * light[c][k];
        value = std::max(0.0, value) + 0.01 * uniform();
        frame[3 * i + c] = static_cast<float>(value * value);  // back to linear for g = 0.5
      }
    }
  }
  std::vector<std::vector<float>> gray_frames(64, std::vector<float>(n));
  for (size_t f = 0; f < gray_frames.size(); ++f) {
    for (int i = 0; i < n; ++i) gray_frames[f][i] = rgb_frames[f][3 * i + 1];
  }
  std::vector<Case> cases;
  // Linear cases: the paper's optimal linear direction (directional_fit off).
  fl::EstimatorOptions linear;
  linear.directional_fit = false;
  cases.push_back({"gray", linear, false, 0});
  cases.push_back({"rgb", linear, true, 0});
  cases.push_back({"rgb_10pct_invalid", linear, true, 10});
  cases.push_back({"rgb_10pct_invalid_changing", linear, true, 10, true});
  fl::EstimatorOptions prior = linear;
  prior.back_prior = 0.1;
  cases.push_back({"rgb_back_prior", prior, true, 0});
  fl::EstimatorOptions robust = prior;
  robust.robust = true;
  cases.push_back({"rgb_robust", robust, true, 0});
  fl::EstimatorOptions nn = prior;
  nn.non_negative = true;
  cases.push_back({"rgb_non_negative", nn, true, 0});
  // The default: directional fit (with the model's direction RTFs when it has them).
  fl::EstimatorOptions directional;
  directional.back_prior = 0.1;
  cases.push_back({"gray_directional", directional, false, 0});
  cases.push_back({"rgb_directional", directional, true, 0});
  cases.push_back({"rgb_directional_10pct_invalid", directional, true, 10});
  cases.push_back({"rgb_directional_10pct_invalid_changing", directional, true, 10, true});
  // The exact (double right-hand side) solve with invalid samples instead of the pseudo-inverse.
  fl::EstimatorOptions directional_exact = directional;
  directional_exact.exact_masked_solve = true;
  cases.push_back({"rgb_directional_10pct_invalid_exact", directional_exact, true, 10});
  fl::EstimatorOptions directional_robust = directional;
  directional_robust.directional_robust = 3;
  cases.push_back({"rgb_directional_robust", directional_robust, true, 0});
  fl::EstimatorOptions directional9 = directional;
  directional9.use_direction_rtfs = false;
  cases.push_back({"rgb_directional_9coef", directional9, true, 0});

  std::string json = "{\n  \"model\": \"" + model_path +
                     "\",\n  \"samples\": " + std::to_string(n) +
                     ",\n  \"frames\": " + std::to_string(frames) + ",\n  \"ns_per_estimate\": {";
  std::printf(
      "face_light_bench: %d samples, %d estimates per case in batches of 64 (ns per estimate: "
      "median and minimum over the batches)\n",
      n, frames);
  volatile float sink = 0;
  const size_t words = (static_cast<size_t>(n) + 63) / 64;
  bool first = true;
  for (size_t k = 0; k < cases.size(); ++k) {
    const Case& c = cases[k];
    if (!only_case.empty() && c.name != only_case) continue;
    const fl::FaceLightEstimator estimator(model, c.options);
    // Validity masks, one per frame of a batch (all the same unless changing_mask).
    std::vector<std::vector<uint64_t>> masks(64, std::vector<uint64_t>(words, ~uint64_t{0}));
    std::mt19937_64 mask_rng(777);
    for (auto& bits : masks) {
      if (c.invalid_every <= 0) continue;
      for (int i = 0; i < n; ++i) {
        const bool invalid =
            c.changing_mask ? mask_rng() % c.invalid_every == 0 : i % c.invalid_every == 0;
        if (invalid) bits[i / 64] &= ~(uint64_t{1} << (i % 64));
      }
    }
    // Many short batches (64 estimates, well below a scheduler time slice): on a loaded machine
    // the minimum is the cost without preemption, the median what a loaded core gives.
    std::vector<double> batches;
    const int batch_frames = 64;
    const int batch_count = std::max(7, frames / batch_frames);
    for (int batch = 0; batch < batch_count; ++batch) {
      const auto start = std::chrono::steady_clock::now();
      for (int f = 0; f < batch_frames; ++f) {
        const std::vector<uint64_t>& bits = masks[f];
        const fl::LightEstimate e = c.rgb ? estimator.EstimateRgb(rgb_frames[f], bits)
                                          : estimator.EstimateGray(gray_frames[f], bits);
        sink = sink + e.coefficients[0][0];
      }
      const auto stop = std::chrono::steady_clock::now();
      batches.push_back(std::chrono::duration<double, std::nano>(stop - start).count() /
                        batch_frames);
    }
    std::sort(batches.begin(), batches.end());
    const double ns = batches[batches.size() / 2];
    const double best = batches.front();
    std::printf("  %-30s %8.0f ns median  %8.0f ns min (%.2f / %.2f us)\n", c.name.c_str(), ns,
                best, ns / 1000, best / 1000);
    char entry[160];
    std::snprintf(entry, sizeof entry, "%s\n    \"%s\": {\"median\": %.0f, \"min\": %.0f}",
                  first ? "" : ",", c.name.c_str(), ns, best);
    first = false;
    json += entry;
  }
  json += "\n  }\n}\n";
  if (!json_path.empty()) {
    std::ofstream out(json_path);
    out << json;
    if (!out) throw fl::FaceLightError(json_path + ": cannot write");
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("face_light_bench", [&] { return Run(argc, argv); });
}
