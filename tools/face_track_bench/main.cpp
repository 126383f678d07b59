// face_track_bench --coverage [--cache DIR] [--redetect-period N] [--no-flow] [--no-clahe]
// [--json]: the tracker over the whole face_orbit stream (see Coverage; --no-flow: without flow
// tracking, --no-clahe: clahe_clip_limit 0).
// face_track_bench [--frames N] [--no-flow] [--no-clahe] [--json]: milliseconds per 640 x 480 RGB
// frame of the face tracker on frames of the face_orbit scenario (rendered once): a full-image
// detection (first frame / lost face), a region re-detection, and the steady state (landmark
// tracking + head pose + sampling the default model's positions), medians over N frames, one core.
// Both: --backend dlib|yunet|haar (detector, default dlib), --yunet-model PATH (default
// $PROBELESS_DATA or <source>/../shared/data, models/yunet_120x160.onnx), --haar-cascade PATH
// (default opencv-data's frontal cascade).
// Prints a table, or one JSON object with --json. Exit 2 on bad options.
#include "probeless/node/main.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "probeless/face_light/model.h"
#include "probeless/face_track/face_tracker.h"
#include "probeless/face_track/sampling.h"
#include "probeless/node/flags.h"
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

// --coverage: every frame of face_orbit in order through one tracker (the demo's stream); per
// frame whether a face is reported, how (detection / landmark tracking / flow) and its error: the
// mean distance of the four canonical combinations (eyes, nose, mouth) to those of the procedural
// head's ground-truth landmarks, in ground-truth inter-ocular distances. A reported face with an
// error above 0.3 counts as wrong (a false positive). Rendered frames are cached in `cache` (PPM
// + landmark text) when given.
int Coverage(bool json, const std::string& cache, int redetect_period, bool flow_tracking,
             bool clahe, const ft::TrackerOptions& base, const std::string& backend) {
  sim::Scenario scenario =
      sim::LoadScenario(std::string(PROBELESS_SOURCE_TREE) + "/data/scenarios/face_orbit.yaml");
  const int count = scenario.frames;
  std::unique_ptr<sim::Simulator> simulator;
  ft::TrackerOptions options = base;
  options.redetect_period = redetect_period;
  options.flow_tracking = flow_tracking;
  options.clahe_clip_limit = clahe ? options.clahe_clip_limit : 0;
  ft::FaceTracker tracker(options);
  int found = 0, detected = 0, flow = 0, wrong = 0, truth_frames = 0;
  double error_sum = 0, quality_sum = 0;
  std::string per_frame;
  for (int i = 0; i < count; ++i) {
    std::vector<uint8_t> rgb;
    std::vector<ft::Point2f> truth(ft::kLandmarkCount);
    int width = 0, height = 0;
    double fx = 0, fy = 0, cx = 0, cy = 0;
    char base[512];
    std::snprintf(base, sizeof base, "%s/face_orbit_%03d", cache.c_str(), i);
    cv::Mat cached;
    if (!cache.empty() && std::filesystem::exists(std::string(base) + ".ppm")) {
      cached = cv::imread(std::string(base) + ".ppm");
    }
    std::FILE* text =
        cache.empty() ? nullptr : std::fopen((std::string(base) + ".txt").c_str(), "r");
    bool have_truth = false;
    if (!cached.empty() && text) {
      cv::cvtColor(cached, cached, cv::COLOR_BGR2RGB);
      width = cached.cols, height = cached.rows;
      rgb.assign(cached.data, cached.data + cached.total() * 3);
      int in_view = 0;
      if (std::fscanf(text, "%lf %lf %lf %lf %d", &fx, &fy, &cx, &cy, &in_view) != 5) {
        throw InputError(std::string(base) +
                         ".txt: malformed cache file (expected 'fx fy cx cy in_view' first)");
      }
      have_truth = in_view != 0;
      for (auto& p : truth) {
        if (std::fscanf(text, "%f %f", &p.x, &p.y) != 2) have_truth = false;
      }
    } else {
      if (!simulator) simulator = std::make_unique<sim::Simulator>(scenario, 2);
      const sim::SimFrame f = simulator->Render(i);
      rgb = f.rgb;
      width = f.camera.width, height = f.camera.height;
      fx = f.camera.fx, fy = f.camera.fy, cx = f.camera.cx, cy = f.camera.cy;
      have_truth = f.face.in_view && f.face.landmarks.size() == ft::kLandmarkCount;
      for (int j = 0; have_truth && j < ft::kLandmarkCount; ++j) {
        truth[j] = {f.face.landmarks[j][0], f.face.landmarks[j][1]};
      }
      if (!cache.empty()) {
        cv::Mat bgr;
        cv::cvtColor(cv::Mat(height, width, CV_8UC3, rgb.data()), bgr, cv::COLOR_RGB2BGR);
        cv::imwrite(std::string(base) + ".ppm", bgr);
        if (std::FILE* out = std::fopen((std::string(base) + ".txt").c_str(), "w")) {
          std::fprintf(out, "%.9g %.9g %.9g %.9g %d\n", fx, fy, cx, cy, have_truth ? 1 : 0);
          for (const auto& p : truth) std::fprintf(out, "%.9g %.9g\n", p.x, p.y);
          std::fclose(out);
        }
      }
    }
    if (text) std::fclose(text);
    const ft::ImageView view{rgb.data(), width, height, static_cast<size_t>(width) * 3,
                             ft::PixelFormat::kRgb};
    const ft::FaceTrack t = tracker.Track(view, ft::Intrinsics{fx, fy, cx, cy});
    truth_frames += have_truth;
    double error = -1;
    if (t.found) {
      ++found;
      detected += t.detected;
      flow += t.flow;
      quality_sum += t.confidence;
      if (have_truth) {
        const auto a = ft::CanonicalLandmarks(t.landmarks);
        const auto b = ft::CanonicalLandmarks(truth);
        const double iod = std::hypot(b[0].x - b[1].x, b[0].y - b[1].y);
        error = 0;
        for (int j = 0; j < 4; ++j) error += std::hypot(a[j].x - b[j].x, a[j].y - b[j].y) / 4;
        error /= iod;
        error_sum += error;
      }
      if (!have_truth || error > 0.3) ++wrong;
    }
    char line[160];
    std::snprintf(line, sizeof line, "%s%d %c %.3f %.2f", i ? ", " : "", i,
                  !t.found     ? '-'
                  : t.detected ? 'D'
                  : t.flow     ? 'F'
                               : 'T',
                  error, t.confidence);
    per_frame += line;
  }
  const int good = found - wrong;
  if (json) {
    std::printf(
        "{\"scenario\":\"face_orbit\",\"frames\":%d,\"frames_with_face_truth\":%d,"
        "\"found\":%d,\"detected\":%d,\"flow_tracked\":%d,\"wrong\":%d,"
        "\"mean_error_iod\":%.4f,\"mean_confidence\":%.3f,\"redetect_period\":%d,"
        "\"backend\":\"%s\"}\n",
        count, truth_frames, found, detected, flow, wrong,
        good > 0 ? error_sum / std::max(found, 1) : 0.0, found ? quality_sum / found : 0.0,
        redetect_period, backend.c_str());
  } else {
    std::printf(
        "face_track_bench --coverage: face_orbit, %d frames (%d with the face in view), "
        "backend %s\n",
        count, truth_frames, backend.c_str());
    std::printf(
        "  face reported in %d frames (%d detections, %d flow-tracked), %d wrong (> 0.3 "
        "iod), mean error %.3f iod, mean confidence %.2f\n",
        found, detected, flow, wrong, found ? error_sum / found : 0.0,
        found ? quality_sum / found : 0.0);
    std::printf(
        "  per frame (index, D detected / T landmark-tracked / F flow / - none, error "
        "iod, confidence):\n  %s\n",
        per_frame.c_str());
  }
  return 0;
}

int Run(int argc, char** argv) {
  int frames = 200;
  bool json = false, coverage = false, flow_tracking = true, clahe = true;
  int redetect_period = 10;
  std::string cache, backend = "dlib";
  ft::TrackerOptions base;
  const char* data = std::getenv("PROBELESS_DATA");
  base.yunet_model_path =
      (data && *data ? std::string(data) : std::string(PROBELESS_SOURCE_TREE) + "/../shared/data") +
      "/models/yunet_120x160.onnx";
  node::FlagParser flags(
      "face_track_bench",
      "milliseconds per 640 x 480 RGB frame of the face tracker on face_orbit frames (detection,\n"
      "region re-detection, steady state), or with --coverage the tracker over the whole stream");
  flags.Add("--frames", &frames, "N", "steady-state frames to time", 10);
  flags.Add("--coverage", &coverage, "every face_orbit frame in order through one tracker");
  flags.Add("--cache", &cache, "DIR", "--coverage: cache rendered frames here");
  flags.Add("--redetect-period", &redetect_period, "N", "--coverage: tracker redetect period", 1);
  flags.AddSwitch(
      "--no-flow", [&] { flow_tracking = false; }, "without flow tracking");
  flags.AddSwitch(
      "--no-clahe", [&] { clahe = false; }, "clahe_clip_limit 0");
  flags.AddCallback(
      "--backend", "dlib|yunet|haar", "face detector",
      [&](const std::string& name) {
        backend = name;
        base.backend = ft::BackendFromName(backend);  // FaceTrackError (an InputError) if unknown
      },
      backend);
  flags.Add("--yunet-model", &base.yunet_model_path, "PATH", "YuNet model");
  flags.Add("--haar-cascade", &base.haar_cascade_path, "PATH", "Haar cascade");
  flags.Add("--json", &json, "one JSON object instead of a table");
  if (!flags.Parse(argc, argv)) return 0;
  if (coverage) return Coverage(json, cache, redetect_period, flow_tracking, clahe, base, backend);
  sim::Scenario scenario =
      sim::LoadScenario(std::string(PROBELESS_SOURCE_TREE) + "/data/scenarios/face_orbit.yaml");
  sim::Simulator simulator(scenario, 2);
  std::vector<sim::SimFrame> rendered;
  for (uint64_t i = 0; i < 4; ++i) rendered.push_back(simulator.Render(i));
  const auto model = face_light::LoadModel(std::string(PROBELESS_SOURCE_TREE) +
                                           "/data/face_light/default_model.txt");
  ft::FaceSampler sampler(model);
  ft::TrackerOptions options = base;
  options.redetect_period = 1 << 30;  // steady state: tracking only
  options.flow_tracking = flow_tracking;
  options.clahe_clip_limit = clahe ? options.clahe_clip_limit : 0;
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
  ft::TrackerOptions every = base;
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
        "{\"image\":\"640x480 rgb8 face_orbit render\",\"backend\":\"%s\",\"samples\":%d,"
        "\"frames\":%d,\"flow_tracking\":%s,\"clahe\":%s,"
        "\"full_detection_ms\":%.2f,\"region_detection_ms\":%.2f,"
        "\"steady_track_ms\":%.2f,\"steady_sample_ms\":%.3f,\"steady_total_ms\":%.2f,"
        "\"amortised_redetect10_ms\":%.2f}\n",
        backend.c_str(), sampler.SampleCount(), frames, flow_tracking ? "true" : "false",
        clahe ? "true" : "false", Median(full), Median(region), Median(track_only),
        Median(sample_only), Median(steady), amortised);
  } else {
    std::printf("face_track_bench: 640x480 rgb8, backend %s, %d samples, medians over %d frames\n",
                backend.c_str(), sampler.SampleCount(), frames);
    std::printf(
        "  full detection     %7.2f ms\n  region detection   %7.2f ms\n"
        "  steady: track      %7.2f ms\n  steady: sample     %7.3f ms\n"
        "  steady: total      %7.2f ms\n  amortised (redetect every 10) %.2f ms\n",
        Median(full), Median(region), Median(track_only), Median(sample_only), Median(steady),
        amortised);
  }
  return 0;
}

int main(int argc, char** argv) {
  return node::RunMain("face_track_bench", [&] { return Run(argc, argv); });
}
