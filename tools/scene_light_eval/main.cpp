// scene_light_eval: evaluates probeless_light's full (Ours) and fast (OursFast) variants.
//
//   scene_light_eval [--sim SCENARIO.yaml | --log FILE.mcap] --json OUT [--plots DIR]
//                    [--frames N] [--directions N] [--bands B] [--aux] [--threads T]
//                    [--camera-truth] [--grey-world] [--quadrature]
//
// --sim (default data/scenarios/room_dynamic.yaml): N frames (default 12) spread evenly over the
// scenario are rendered in-process; each variant runs on the noise-free render (depth, normals,
// colour: the estimator in isolation) — the top-level `full` / `fast` objects — and on the sensor
// output (depth16 with noise, quantisation and holes, normals from depth, noisy rgb8) — the
// `with_sensor_noise` object. --log reads /camera/camera_info, /camera/image, /camera/depth and
// /groundtruth/light from an MCAP log (sensor data only; normals from depth), matched by
// header.stamp_ns (ROS 2 logs carry no sequence). --aux adds left/right/top orthographic views
// traced from the scene (--sim).
// Ground truth (--sim): light::SurfaceLightingTruth, the light averaged over the visible surface
// points (what a distant-light fit to those surfaces can recover; equal to the light at the
// camera for distant lights); --camera-truth scores against the light at the camera
// (/groundtruth/light, the only truth a --log has). Errors: the angle between the estimated and
// the true dominant direction (frames whose truth has an enabled light: a switched-off interval
// without any light is left out), the same against the light at the camera
// (dominant_dir_error_vs_camera_light_deg_median), and |l - l_true| / |l_true| over bands 0-2 of
// the grey (mean RGB) truth. --grey-world: one uniform albedo (no chromaticity groups);
// --quadrature: eq. 6 as printed (no analytic unoccluded transfer) — ablations. Timings are per
// frame at the stream's resolution with --threads workers (default 2): wall ms, process CPU ms of
// the transfer (all threads) and thread CPU ms of the estimate. Output: one JSON object; plots as
// PNG (lat-long maps, error over time, estimated and true direction over time).
#include "probeless/node/main.h"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "probeless/light/estimate.h"
#include "probeless/light/messages.h"
#include "probeless/light/sim_buffers.h"
#include "probeless/light/transfer.h"
#include "probeless/msgs/msgs.h"
#include "probeless/replay/sources.h"
#include "probeless/sh/sh.h"
#include "probeless/sim/scenario.h"
#include "probeless/sim/simulator.h"

namespace {

using namespace probeless;
using Clock = std::chrono::steady_clock;

struct Options {
  std::string sim = "data/scenarios/room_dynamic.yaml";
  std::string log;
  std::string json;
  std::string plots;
  int frames = 12;
  int directions = 32;
  int bands = 4;
  int threads = 2;
  bool aux = false;
  bool camera_truth = false;  // --camera-truth: score against the light at the camera
  bool grey_world = false;    // --grey-world: one uniform albedo (no chromaticity groups)
  bool quadrature = false;    // --quadrature: eq. 6 as printed (no analytic unoccluded part)
};

// One evaluated frame of one variant.
struct Sample {
  double time_s = 0;
  double dir_error_deg = NAN;         // NAN when the ground truth has no dominant light
  double dir_error_camera_deg = NAN;  // against the light at the camera (--sim only)
  double sh_rel_error = NAN;
  double ms_transfer = 0;
  double ms_estimate = 0;
  double cpu_ms_transfer = 0;     // process CPU time of the transfer call (all threads)
  double cpu_ms_estimate = 0;     // CPU time of the estimate (one thread)
  std::vector<double> estimate;   // coefficients
  std::array<float, 27> truth{};  // 9 x RGB
  std::array<float, 3> estimate_dir{0, 0, 0}, truth_dir{0, 0, 0};  // camera frame, 0 = none
};

struct Series {
  std::vector<Sample> samples;
};

double Quantile(std::vector<double> v, double q) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return std::isnan(x); }), v.end());
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const double pos = q * (v.size() - 1);
  const size_t i = static_cast<size_t>(pos);
  const double f = pos - i;
  return i + 1 < v.size() ? v[i] * (1 - f) + v[i + 1] * f : v[i];
}

std::string Num(double v) {
  if (std::isnan(v)) return "null";
  std::ostringstream s;
  s.precision(5);
  s << v;
  return s.str();
}

std::string SeriesJson(const Series& s) {
  std::vector<double> dir, dir_cam, sh_err, ms_t, ms_e, cpu_t, cpu_e;
  for (const auto& x : s.samples) {
    dir.push_back(x.dir_error_deg);
    dir_cam.push_back(x.dir_error_camera_deg);
    sh_err.push_back(x.sh_rel_error);
    ms_t.push_back(x.ms_transfer);
    ms_e.push_back(x.ms_estimate);
    cpu_t.push_back(x.cpu_ms_transfer);
    cpu_e.push_back(x.cpu_ms_estimate);
  }
  std::ostringstream o;
  o << "{\"frames\": " << s.samples.size()
    << ", \"dominant_dir_error_deg_median\": " << Num(Quantile(dir, 0.5))
    << ", \"dominant_dir_error_deg_p90\": " << Num(Quantile(dir, 0.9))
    << ", \"sh_rel_error_median\": " << Num(Quantile(sh_err, 0.5))
    << ", \"ms_transfer_median\": " << Num(Quantile(ms_t, 0.5))
    << ", \"ms_estimate_median\": " << Num(Quantile(ms_e, 0.5))
    << ", \"cpu_ms_transfer_median\": " << Num(Quantile(cpu_t, 0.5))
    << ", \"cpu_ms_estimate_median\": " << Num(Quantile(cpu_e, 0.5))
    << ", \"dominant_dir_error_vs_camera_light_deg_median\": " << Num(Quantile(dir_cam, 0.5))
    << "}";
  return o.str();
}

struct Variant {
  light::TransferComputer computer;
  light::EstimateOptions estimate;
  light::TransferResult result;  // reused across frames, as the node does
  Series clean, noisy;
  Variant(const light::TransferOptions& o, const light::EstimateOptions& e)
      : computer(o), estimate(e) {}
};

double CpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

// Runs one variant on one frame and scores it against the ground truth.
Sample RunFrame(Variant& v, const light::GeometryView& g, std::span<const float> grey,
                std::span<const uint8_t> colour, const light::AuxiliaryBuffers& aux,
                const msgs::ShLight& truth, double time_s,
                const msgs::ShLight* camera_truth = nullptr) {
  Sample s;
  s.time_s = time_s;
  light::TransferResult& t = v.result;
  const double c0 = CpuMs();
  const auto t0 = Clock::now();
  v.computer.Compute(g, aux, nullptr, &t);
  const auto t1 = Clock::now();
  s.cpu_ms_transfer = CpuMs() - c0;
  const double c1 = ThreadCpuMs();
  const light::LightEstimate e = light::EstimateLight(t, grey, v.estimate, colour);
  s.cpu_ms_estimate = ThreadCpuMs() - c1;
  const auto t2 = Clock::now();
  s.ms_transfer = std::chrono::duration<double, std::milli>(t1 - t0).count();
  s.ms_estimate = std::chrono::duration<double, std::milli>(t2 - t1).count();
  s.estimate = e.coefficients;
  for (int n = 0; n < 9; ++n) {
    for (int c = 0; c < 3; ++c) s.truth[n * 3 + c] = truth.coefficients[n][c];
  }
  auto angle = [&](const float* d) {
    if (!e.valid || (d[0] == 0 && d[1] == 0 && d[2] == 0)) return NAN * 1.0;
    const double dot = e.dominant_direction[0] * d[0] + e.dominant_direction[1] * d[1] +
                       e.dominant_direction[2] * d[2];
    return std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / std::numbers::pi;
  };
  s.dir_error_deg = angle(truth.dominant_direction);
  for (int k = 0; k < 3; ++k) {
    s.truth_dir[k] = truth.dominant_direction[k];
    if (e.valid) s.estimate_dir[k] = e.dominant_direction[k];
  }
  if (camera_truth != nullptr) s.dir_error_camera_deg = angle(camera_truth->dominant_direction);
  if (e.valid) {
    double num = 0, den = 0;
    for (int n = 0; n < 9 && n < static_cast<int>(e.coefficients.size()); ++n) {
      const double grey_truth =
          (truth.coefficients[n][0] + truth.coefficients[n][1] + truth.coefficients[n][2]) / 3;
      num += (e.coefficients[n] - grey_truth) * (e.coefficients[n] - grey_truth);
      den += grey_truth * grey_truth;
    }
    if (den > 0) s.sh_rel_error = std::sqrt(num / den);
  }
  return s;
}

constexpr int kMapWidth = 256, kMapHeight = 128;

std::vector<float> LatLongValues(const std::vector<float>& coefficients, int bands) {
  std::vector<float> out(kMapWidth * kMapHeight);
  sh::RenderLatLong(coefficients, bands, 1, kMapWidth, kMapHeight, out);
  return out;
}

// Colour-mapped lat-long map, 0 .. `max` -> black .. yellow (inferno).
cv::Mat LatLongImage(const std::vector<float>& values, float max) {
  cv::Mat img(kMapHeight, kMapWidth, CV_8UC1);
  for (int i = 0; i < kMapWidth * kMapHeight; ++i) {
    img.data[i] = static_cast<uint8_t>(std::clamp(values[i] / max * 255.0f, 0.0f, 255.0f));
  }
  cv::Mat colour;
  cv::applyColorMap(img, colour, cv::COLORMAP_INFERNO);
  return colour;
}

void WritePlots(const std::string& dir, const Series& full, const Series& fast) {
  std::filesystem::create_directories(dir);
  // Lat-long maps, truth over estimate, for up to 4 frames of the full variant.
  std::vector<cv::Mat> columns;
  const size_t n = full.samples.size();
  for (size_t k = 0; k < std::min<size_t>(4, n); ++k) {
    const Sample& s = full.samples[k * n / std::min<size_t>(4, n)];
    std::vector<float> truth(9), est;
    for (int i = 0; i < 9; ++i) {
      truth[i] = (s.truth[3 * i] + s.truth[3 * i + 1] + s.truth[3 * i + 2]) / 3;
    }
    for (double c : s.estimate) est.push_back(static_cast<float>(c));
    if (est.empty()) continue;
    const int bands = static_cast<int>(std::lround(std::sqrt(est.size())));
    const auto tv = LatLongValues(truth, 3), ev = LatLongValues(est, bands);
    const float max = std::max(1e-6f, *std::max_element(tv.begin(), tv.end()));
    cv::Mat a = LatLongImage(tv, max), b = LatLongImage(ev, max), col;
    cv::putText(a, "truth t=" + Num(s.time_s) + "s", {4, 14}, cv::FONT_HERSHEY_SIMPLEX, 0.4,
                {255, 255, 255});
    cv::putText(b, "estimate (full)", {4, 14}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {255, 255, 255});
    cv::vconcat(a, b, col);
    columns.push_back(col);
  }
  if (!columns.empty()) {
    cv::Mat sheet;
    cv::hconcat(columns, sheet);
    cv::imwrite(dir + "/scene_light_latlong.png", sheet);
  }
  // Dominant-direction error over time.
  const int W = 640, H = 280, m = 40;
  cv::Mat plot(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  double t_max = 0;
  for (const auto& s : full.samples) t_max = std::max(t_max, s.time_s);
  if (t_max <= 0) t_max = 1;
  const double e_max = 60;
  cv::rectangle(plot, {m, 10}, {W - 10, H - m}, {0, 0, 0});
  for (double e = 0; e <= e_max; e += 10) {
    const int y = static_cast<int>(H - m - e / e_max * (H - m - 10));
    cv::line(plot, {m, y}, {W - 10, y}, {220, 220, 220});
    cv::putText(plot, Num(e), {4, y + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.35, {0, 0, 0});
  }
  auto draw = [&](const Series& s, cv::Scalar colour) {
    cv::Point prev(-1, -1);
    for (const auto& x : s.samples) {
      if (std::isnan(x.dir_error_deg)) {
        prev = {-1, -1};
        continue;
      }
      const cv::Point p(
          static_cast<int>(m + x.time_s / t_max * (W - m - 10)),
          static_cast<int>(H - m - std::min(x.dir_error_deg, e_max) / e_max * (H - m - 10)));
      cv::circle(plot, p, 3, colour, cv::FILLED);
      if (prev.x >= 0) cv::line(plot, prev, p, colour);
      prev = p;
    }
  };
  draw(full, {200, 80, 0});
  draw(fast, {0, 120, 255});
  cv::putText(plot, "dominant direction error (deg) vs time (s); blue = full, orange = fast",
              {m, H - 12}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {0, 0, 0});
  cv::imwrite(dir + "/scene_light_error.png", plot);

  // Estimated and true dominant direction over time: elevation (towards the camera's up, -y) and
  // azimuth (atan2(x, z), 0 = straight ahead) in the camera frame.
  const int PH = 200;
  cv::Mat dirs(2 * PH + 30, W, CV_8UC3, cv::Scalar(255, 255, 255));
  auto panel = [&](int top, const char* name, double lo, double hi, auto value) {
    cv::rectangle(dirs, {m, top + 5}, {W - 10, top + PH - 15}, {0, 0, 0});
    for (double a = lo; a <= hi; a += 45) {
      const int y = static_cast<int>(top + PH - 15 - (a - lo) / (hi - lo) * (PH - 20));
      cv::line(dirs, {m, y}, {W - 10, y}, {220, 220, 220});
      cv::putText(dirs, Num(a), {2, y + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.35, {0, 0, 0});
    }
    cv::putText(dirs, name, {m + 4, top + 18}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {0, 0, 0});
    auto draw_series = [&](const Series& series, bool truth, cv::Scalar colour) {
      for (const auto& x : series.samples) {
        const auto& d = truth ? x.truth_dir : x.estimate_dir;
        if (d[0] == 0 && d[1] == 0 && d[2] == 0) continue;
        const double v = std::clamp(value(d), lo, hi);
        const cv::Point p(static_cast<int>(m + x.time_s / t_max * (W - m - 10)),
                          static_cast<int>(top + PH - 15 - (v - lo) / (hi - lo) * (PH - 20)));
        if (truth) {
          cv::drawMarker(dirs, p, colour, cv::MARKER_CROSS, 10, 2);
        } else {
          cv::circle(dirs, p, 3, colour, cv::FILLED);
        }
      }
    };
    draw_series(full, true, {0, 0, 0});
    draw_series(full, false, {200, 80, 0});
    draw_series(fast, false, {0, 120, 255});
  };
  constexpr double kDeg = 180 / std::numbers::pi;
  panel(0, "elevation (deg)", -90, 90, [&](const std::array<float, 3>& d) {
    return std::asin(std::clamp(-d[1], -1.0f, 1.0f)) * kDeg;
  });
  panel(PH, "azimuth (deg)", -180, 180,
        [&](const std::array<float, 3>& d) { return std::atan2(d[0], d[2]) * kDeg; });
  cv::putText(dirs,
              "dominant direction vs time, camera frame: black + truth, blue full, orange fast",
              {m, 2 * PH + 20}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {0, 0, 0});
  cv::imwrite(dir + "/scene_light_direction.png", dirs);
}

int Run(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw node::UsageError(a + " needs a value");
      return argv[++i];
    };
    if (a == "--sim")
      o.sim = value();
    else if (a == "--log")
      o.log = value();
    else if (a == "--json")
      o.json = value();
    else if (a == "--plots")
      o.plots = value();
    else if (a == "--frames")
      o.frames = static_cast<int>(node::ParseNumberOption(a, value()));
    else if (a == "--directions")
      o.directions = static_cast<int>(node::ParseNumberOption(a, value()));
    else if (a == "--bands")
      o.bands = static_cast<int>(node::ParseNumberOption(a, value()));
    else if (a == "--threads")
      o.threads = static_cast<int>(node::ParseNumberOption(a, value()));
    else if (a == "--aux")
      o.aux = true;
    else if (a == "--camera-truth")
      o.camera_truth = true;
    else if (a == "--grey-world")
      o.grey_world = true;
    else if (a == "--quadrature")
      o.quadrature = true;
    else
      throw node::UsageError("unknown option '" + a + "'");
  }
  if (o.json.empty()) throw node::UsageError("--json OUT is required");
  if (o.frames < 1) throw node::UsageError("--frames must be >= 1");
  light::TransferOptions full_o;
  full_o.directions = o.directions;
  full_o.bands = o.bands;
  full_o.threads = o.threads;
  full_o.analytic_unoccluded = !o.quadrature;
  light::TransferOptions fast_o = full_o;
  fast_o.subsample = 4;
  light::EstimateOptions eo;
  if (o.grey_world) eo.albedo_groups = 0;
  Variant full(full_o, eo), fast(fast_o, eo);
  const auto start = Clock::now();
  std::string source_name;
  if (o.log.empty()) {
    std::string path = o.sim;
    if (!std::filesystem::exists(path)) path = std::string(PROBELESS_SOURCE_TREE) + "/" + o.sim;
    source_name = o.sim;
    sim::Simulator simulator(sim::LoadScenario(path), o.threads);
    const uint64_t total = simulator.scenario().frames;
    const int count = static_cast<int>(std::min<uint64_t>(o.frames, total));
    for (int k = 0; k < count; ++k) {
      const uint64_t index = static_cast<uint64_t>(k) * total / count;
      const sim::SimFrame f = simulator.Render(index);
      auto to_msg = [](const raytrace::LightingGroundTruth& l) {
        msgs::ShLight m;
        for (int n = 0; n < 9; ++n) {
          m.coefficients[n][0] = l.sh[n].x;
          m.coefficients[n][1] = l.sh[n].y;
          m.coefficients[n][2] = l.sh[n].z;
        }
        m.dominant_direction[0] = l.dominant_direction.x;
        m.dominant_direction[1] = l.dominant_direction.y;
        m.dominant_direction[2] = l.dominant_direction.z;
        return m;
      };
      const msgs::ShLight camera_truth = to_msg(f.light);
      const msgs::ShLight truth =
          o.camera_truth ? camera_truth : to_msg(light::SurfaceLightingTruth(simulator.scene(), f));
      light::AuxiliaryStorage aux;
      if (o.aux) aux = light::RenderAuxiliaryViews(simulator.scene(), f.camera, {});
      for (bool sensor : {false, true}) {
        const light::GeometryStorage g = light::GeometryFromSimFrame(f, sensor);
        for (Variant* v : {&full, &fast}) {
          (sensor ? v->noisy : v->clean)
              .samples.push_back(RunFrame(*v, g.View(), g.grey, g.colour, aux.buffers, truth,
                                          f.time_s, &camera_truth));
        }
      }
      std::fprintf(stderr, "frame %llu (%d/%d): full %.1f deg, fast %.1f deg\n",
                   static_cast<unsigned long long>(index), k + 1, count,
                   full.clean.samples.back().dir_error_deg,
                   fast.clean.samples.back().dir_error_deg);
    }
  } else {
    source_name = o.log;
    auto source = replay::OpenMcapSource(o.log);
    std::map<int64_t, msgs::ShLight> truths;
    struct Pending {
      std::vector<float> depth, normals, grey;
      light::Intrinsics k;
      int w = 0, h = 0;
      double time_s = 0;
    };
    std::map<int64_t, Pending> frames;
    std::optional<msgs::CameraInfo> info;
    std::map<int64_t, std::vector<float>> greys;
    std::map<int64_t, std::vector<uint8_t>> colours;
    while (auto m = source->Next()) {
      const auto& topic = source->topics()[m->topic_index];
      const auto bytes = m->message.bytes();
      if (topic.topic == "/camera/camera_info") {
        info = *msgs::ReadMessage<msgs::CameraInfo>(bytes);
      } else if (topic.topic == "/camera/image") {
        const auto img = msgs::ReadMessage<msgs::Image>(bytes);
        light::GreyFromImage(*img, img.payload, img->width, img->height,
                             &greys[img->header.stamp_ns], &colours[img->header.stamp_ns]);
      } else if (topic.topic == "/camera/depth" && info) {
        const auto d = msgs::ReadMessage<msgs::Image>(bytes);
        Pending p;
        light::GeometryFromDepthImage(*d, d.payload, *info, &p.depth, &p.normals);
        p.k = light::IntrinsicsFrom(*info, d->width, d->height);
        p.w = d->width;
        p.h = d->height;
        p.time_s = m->log_time_ns * 1e-9;
        frames[d->header.stamp_ns] = std::move(p);
      } else if (topic.topic == "/groundtruth/light") {
        const auto l = msgs::ReadMessage<msgs::ShLight>(bytes);
        truths[l->header.stamp_ns] = *l;
      }
    }
    std::vector<int64_t> usable;
    for (const auto& [seq, p] : frames) {
      if (truths.count(seq) && greys.count(seq)) usable.push_back(seq);
    }
    const int count = std::min<int>(o.frames, usable.size());
    for (int k = 0; k < count; ++k) {
      const int64_t seq = usable[static_cast<size_t>(k) * usable.size() / count];
      const Pending& p = frames[seq];
      const light::GeometryView g{p.w, p.h, p.k, p.depth, p.normals, {}};
      for (Variant* v : {&full, &fast}) {
        v->noisy.samples.push_back(
            RunFrame(*v, g, greys[seq], colours[seq], {}, truths[seq], p.time_s));
      }
    }
    // A log carries sensor data only: report it as both the top level and with_sensor_noise.
    full.clean = full.noisy;
    fast.clean = fast.noisy;
  }
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  std::ofstream out(o.json);
  if (!out) throw node::UsageError("cannot write '" + o.json + "'");
  out << "{\n  \"source\": \"" << source_name << "\",\n  \"directions\": " << o.directions
      << ",\n  \"bands\": " << o.bands << ",\n  \"threads\": " << o.threads
      << ",\n  \"aux_views\": " << (o.aux ? "true" : "false") << ",\n  \"truth\": \""
      << (o.log.empty() && !o.camera_truth ? "surface" : "camera") << "\""
      << ",\n  \"albedo_groups\": " << eo.albedo_groups
      << ",\n  \"analytic_unoccluded\": " << (o.quadrature ? "false" : "true")
      << ",\n  \"max_rows_per_bin\": " << eo.max_rows_per_bin
      << ",\n  \"full\": " << SeriesJson(full.clean) << ",\n  \"fast\": " << SeriesJson(fast.clean)
      << ",\n  \"with_sensor_noise\": {\"full\": " << SeriesJson(full.noisy)
      << ", \"fast\": " << SeriesJson(fast.noisy) << "},\n  \"seconds\": " << Num(seconds)
      << "\n}\n";
  if (!o.plots.empty()) WritePlots(o.plots, full.clean, fast.clean);
  std::printf("full %s\nfast %s\nwith sensor noise: full %s\n                   fast %s\n",
              SeriesJson(full.clean).c_str(), SeriesJson(fast.clean).c_str(),
              SeriesJson(full.noisy).c_str(), SeriesJson(fast.noisy).c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return node::RunMain<light::LightError, sim::ScenarioError>("scene_light_eval",
                                                              [&] { return Run(argc, argv); });
}
