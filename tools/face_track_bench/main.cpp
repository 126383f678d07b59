// face_track_bench [--frames N] [--json]: milliseconds per 640 x 480 RGB frame of the face tracker
// on frames of the face_orbit scenario (rendered once): a full-image detection (first frame /
// lost face), a region re-detection, and the steady state (landmark tracking + head pose +
// sampling the default model's 303 positions), medians over N frames, one core. Prints a table,
// or one JSON object with --json. Exit 2 on bad options.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "probeless/face_light/model.h"
#include "probeless/face_track/face_tracker.h"
#include "probeless/face_track/sampling.h"
#include "probeless/sim/scenario.h"
#include "probeless/sim/simulator.h"

namespace {

using namespace probeless;
namespace ft = probeless::face_track;
using Clock = std::chrono::steady_clock;

double Ms(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  int frames = 200;
  bool json = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--json")) {
      json = true;
    } else if (!std::strcmp(argv[i], "--frames") && i + 1 < argc) {
      frames = std::max(10, std::atoi(argv[++i]));
    } else {
      std::fprintf(stderr,
                   "[error] [face_track_bench] usage: face_track_bench [--frames N] [--json]\n");
      return 2;
    }
  }
  try {
    sim::Scenario scenario =
        sim::LoadScenario(std::string(PROBELESS_SOURCE_TREE) + "/data/scenarios/face_orbit.yaml");
    sim::Simulator simulator(scenario, 2);
    std::vector<sim::SimFrame> rendered;
    for (uint64_t i = 0; i < 4; ++i) rendered.push_back(simulator.Render(i));
    const auto model = face_light::LoadModel(std::string(PROBELESS_SOURCE_TREE) +
                                             "/data/face_light/default_model.txt");
    ft::FaceSampler sampler(model);
    ft::TrackerOptions options;
    options.redetect_period = 1 << 30;  // steady state: tracking only
    ft::FaceTracker tracker(options);
    auto view = [&](int i) {
      const auto& f = rendered[i % rendered.size()];
      return ft::ImageView{f.rgb.data(), f.camera.width, f.camera.height,
                           static_cast<size_t>(f.camera.width) * 3, ft::PixelFormat::kRgb};
    };
    const ft::Intrinsics k{525, 525, 319.5, 239.5};
    // Full detections.
    std::vector<double> full, steady, track_only, sample_only, region;
    for (int i = 0; i < 10; ++i) {
      tracker.Reset();
      const auto t0 = Clock::now();
      const auto t = tracker.Track(view(i), k);
      full.push_back(Ms(t0, Clock::now()));
      if (!t.found) throw std::runtime_error("no face in the face_orbit render");
    }
    for (int i = 0; i < frames; ++i) {
      const auto t0 = Clock::now();
      const auto t = tracker.Track(view(i), k);
      const auto t1 = Clock::now();
      if (!t.found) throw std::runtime_error("lost the face in the steady state");
      const auto s = sampler.Sample(view(i), t);
      const auto t2 = Clock::now();
      track_only.push_back(Ms(t0, t1));
      sample_only.push_back(Ms(t1, t2));
      steady.push_back(Ms(t0, t2));
    }
    ft::TrackerOptions every;
    every.redetect_period = 1;  // a region detection every frame
    ft::FaceTracker redetecting(every);
    redetecting.Track(view(0), k);
    for (int i = 0; i < 20; ++i) {
      const auto t0 = Clock::now();
      redetecting.Track(view(i), k);
      region.push_back(Ms(t0, Clock::now()));
    }
    const double period = 10;
    const double amortised =
        (Median(steady) * (period - 1) + Median(region) + Median(sample_only)) / period;
    if (json) {
      std::printf(
          "{\"image\":\"640x480 rgb8 face_orbit render\",\"samples\":%d,\"frames\":%d,"
          "\"full_detection_ms\":%.2f,\"region_detection_ms\":%.2f,"
          "\"steady_track_ms\":%.2f,\"steady_sample_ms\":%.3f,\"steady_total_ms\":%.2f,"
          "\"amortised_redetect10_ms\":%.2f}\n",
          sampler.SampleCount(), frames, Median(full), Median(region), Median(track_only),
          Median(sample_only), Median(steady), amortised);
    } else {
      std::printf("face_track_bench: 640x480 rgb8, %d samples, medians over %d frames\n",
                  sampler.SampleCount(), frames);
      std::printf(
          "  full detection     %7.2f ms\n  region detection   %7.2f ms\n"
          "  steady: track      %7.2f ms\n  steady: sample     %7.3f ms\n"
          "  steady: total      %7.2f ms\n  amortised (redetect every 10) %.2f ms\n",
          Median(full), Median(region), Median(track_only), Median(sample_only), Median(steady),
          amortised);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [face_track_bench] %s\n", e.what());
    return 1;
  }
  return 0;
}
