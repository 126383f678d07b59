// fusion_eval: measures the reconstruction pipeline.
//
//   fusion_eval --sevenscenes DIR [--frames A-B] [--peer opencv] [--peer-frames N] --json OUT
//               (--tum DIR instead: a TUM RGB-D folder, e.g. a generated scene, docs/sim.md; the
//               same figures and options)
//               [--mesh OUT.ply] [--poses OUT.txt] [--threads N] [--no-merge] [--verbose]
//               [--volume-size M --volume-origin X,Y,Z [--volume-resolution N]]
//   fusion_eval --sim SCENARIO [--frames A-B] --json OUT [--volume-size M] [--volume-origin X,Y,Z]
//
// 7-Scenes: frames are decoded up front (not timed), then tracked, integrated, raycast and merged;
// JSON keys frames, ate_rmse_m (translation RMSE after aligning the first pose: accumulated
// drift), ate_max_m, ate_aligned_rmse_m / ate_aligned_max_m (the TUM RGB-D benchmark's ATE: after
// the least-squares rigid alignment of all positions, Horn 1987), tracking_lost,
// ms_per_frame_median (wall, all stages incl. preprocessing), ms_<stage>_median (wall) and
// cpu_ms_<stage>_median (process CPU time, both threads) for preprocess, icp, integrate, raycast
// and merge, cpu_ms_per_frame_median, threads, volume_size_m, volume_resolution,
// volume_origin_{x,y,z} (the volume used, also printed); --poses writes one line per frame:
// index, estimated and ground-truth 3x4 [R | t]. With --peer opencv the first --peer-frames
// (100) frames also run through OpenCV 4.6's kinfu TSDF volume (cv::kinfu::makeVolume, same
// volume / truncation / max weight) and cv::rgbd::ICPOdometry (frame to frame, same 3-level
// pyramid and iterations), adding peer_frames, peer_ms_per_frame_median, peer_ate_rmse_m,
// peer_ate_aligned_rmse_m, speedup_median. 7-Scenes colour is registered to depth by the dataset
// source (Kinect v1 nominal colour calibration, docs/dataset.md) and guides the merge; tracking
// uses depth only. The default volume is the library's (256^3 over 2 m, see recon::VolumeOptions).
// Tuning knobs for experiments (environment): FUSION_EVAL_ICP=a,b,c (iterations),
// FUSION_EVAL_TRACK_LEVEL, FUSION_EVAL_MAXDIST (m), FUSION_EVAL_MAXW, FUSION_EVAL_TRUNC (m),
// FUSION_EVAL_BILATERAL (radius), FUSION_EVAL_ANGLE (deg), FUSION_EVAL_MERGE_GATE /
// FUSION_EVAL_MERGE_MAJORITY (0 = the paper's eq. 3-5 exactly), FUSION_EVAL_MERGE_SIGMAS /
// FUSION_EVAL_MERGE_QUANT (MergeOptions::lambda_d_sigmas / noise_quantisation_per_m; 0 = the
// paper's fixed lambda_D), FUSION_EVAL_DEPTH_SCALE (multiplies the depth), FUSION_EVAL_DEPTH_MAX
// (m, drops farther depth), FUSION_EVAL_FOCAL (replaces fx = fy), FUSION_EVAL_K1 (k1[,k2]: radial
// undistortion of the depth images, nearest neighbour), FUSION_EVAL_OBSERVABILITY (good,soft,hard),
// FUSION_EVAL_MATCHED_OBSERVABILITY (0: the observability cue from the frame's geometry only).
// --min-inliers overrides the tracking-quality threshold.
//
// Sim: renders the scenario (noise-free depth = reference), runs the pipeline with the ground-
// truth poses, and reports the mean absolute depth error and hole fraction of raw depth (D_c),
// the volume (D_v), the merge passes D' (merge_pass1), D'' (merge_pass2) and G_r (D''', merged)
// against the reference, over all pixels and over the moving object ("waved_box"), each also
// over the pixels where raw is valid (the same set for every source), and the error by
// chessboard distance to the object's silhouette (inside in1, in2, in3, in4_6, in7up; outside
// out1..out3; printed as a table). Exit 0, 2 on bad options or input, 1 otherwise.
#include "probeless/node/main.h"

#include <time.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/rgbd.hpp>
#include <opencv2/rgbd/volume.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "probeless/dataset/datasets.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/flags.h"
#include "probeless/parse/number.h"
#include "probeless/recon/msgs_io.h"
#include "probeless/recon/pipeline.h"
#include "probeless/sim/scenario.h"
#include "probeless/sim/simulator.h"

namespace {

using namespace probeless;

using node::UsageError;

constexpr const char* kDescription =
    "measures the reconstruction pipeline: --sevenscenes DIR | --tum DIR | --sim SCENARIO, and\n"
    "--json OUT, are required.\n"
    "environment knobs (experiments): FUSION_EVAL_ICP=a,b,c, FUSION_EVAL_TRACK_LEVEL,\n"
    "  FUSION_EVAL_MAXDIST, FUSION_EVAL_MAXW, FUSION_EVAL_TRUNC, FUSION_EVAL_BILATERAL,\n"
    "  FUSION_EVAL_ANGLE, FUSION_EVAL_MERGE_GATE, FUSION_EVAL_MERGE_MAJORITY (0|1),\n"
    "  FUSION_EVAL_MERGE_SIGMAS, FUSION_EVAL_MERGE_QUANT, FUSION_EVAL_DEPTH_SCALE,\n"
    "  FUSION_EVAL_DEPTH_MAX, FUSION_EVAL_FOCAL, FUSION_EVAL_K1=k1[,k2], FUSION_EVAL_NORMALS,\n"
    "  FUSION_EVAL_OBSERVABILITY=good,soft,hard, FUSION_EVAL_NORMAL_BLOCK\n"
    "exit code: 0 done, 2 bad options or input, 1 otherwise";

// An environment knob as a number (parse::ParseDouble / ParseInteger; a malformed value is an
// error naming the variable, never a silent 0).
std::optional<double> KnobDouble(const char* name,
                                 double min = std::numeric_limits<double>::lowest()) {
  const char* text = std::getenv(name);
  if (!text) return std::nullopt;
  return parse::ParseDouble(name, text, min);
}
std::optional<int> KnobInt(const char* name, int min, int max = std::numeric_limits<int>::max()) {
  const char* text = std::getenv(name);
  if (!text) return std::nullopt;
  return parse::ParseInteger<int>(name, text, min, max);
}

struct Frame {
  recon::DepthImage depth;
  recon::GreyImage grey;
  recon::Pose truth;
};

// Process CPU time (all threads), milliseconds.
double CpuMs() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// FUSION_EVAL_MERGE_GATE=0 / FUSION_EVAL_MERGE_MAJORITY=0 switch the merge's two deviations from
// the paper off (recon::MergeOptions::depth_gated_medians / volume_needs_majority).
void ApplyMergeKnobs(recon::MergeOptions& merge) {
  if (const auto g = KnobInt("FUSION_EVAL_MERGE_GATE", 0, 1)) merge.depth_gated_medians = *g;
  if (const auto m = KnobInt("FUSION_EVAL_MERGE_MAJORITY", 0, 1)) {
    merge.volume_needs_majority = *m;
  }
  if (const auto k = KnobDouble("FUSION_EVAL_MERGE_SIGMAS", 0)) merge.lambda_d_sigmas = *k;
  if (const auto q = KnobDouble("FUSION_EVAL_MERGE_QUANT", 0)) merge.noise_quantisation_per_m = *q;
}

struct Ate {
  double rmse = 0;
  double max = 0;
};
Ate ComputeAte(const std::vector<recon::Pose>& est, const std::vector<recon::Pose>& truth) {
  Ate a;
  if (est.empty()) return a;
  double sum2 = 0;
  for (size_t i = 0; i < est.size(); ++i) {
    // Align the first pose: estimate i in the ground-truth world.
    const recon::Pose aligned = truth[0] * est[0].Inverse() * est[i];
    const double dx = aligned.t[0] - truth[i].t[0], dy = aligned.t[1] - truth[i].t[1],
                 dz = aligned.t[2] - truth[i].t[2];
    const double e = std::sqrt(dx * dx + dy * dy + dz * dz);
    sum2 += e * e;
    a.max = std::max(a.max, e);
  }
  a.rmse = std::sqrt(sum2 / est.size());
  return a;
}

// Eigenvector of the largest eigenvalue of a symmetric 4x4 matrix (cyclic Jacobi rotations).
std::array<double, 4> LargestEigenvector(double a[4][4]) {
  double v[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}};
  for (int sweep = 0; sweep < 50; ++sweep) {
    double off = 0;
    for (int p = 0; p < 4; ++p)
      for (int q = p + 1; q < 4; ++q) off += a[p][q] * a[p][q];
    if (off < 1e-30) break;
    for (int p = 0; p < 4; ++p) {
      for (int q = p + 1; q < 4; ++q) {
        if (std::fabs(a[p][q]) < 1e-300) continue;
        const double theta = (a[q][q] - a[p][p]) / (2 * a[p][q]);
        const double t = (theta >= 0 ? 1 : -1) / (std::fabs(theta) + std::sqrt(theta * theta + 1));
        const double c = 1 / std::sqrt(t * t + 1), s = t * c;
        for (int k = 0; k < 4; ++k) {  // A <- A J (columns p, q)
          const double akp = a[k][p], akq = a[k][q];
          a[k][p] = c * akp - s * akq;
          a[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < 4; ++k) {  // A <- J^T A (rows p, q)
          const double apk = a[p][k], aqk = a[q][k];
          a[p][k] = c * apk - s * aqk;
          a[q][k] = s * apk + c * aqk;
        }
        for (int k = 0; k < 4; ++k) {
          const double vkp = v[k][p], vkq = v[k][q];
          v[k][p] = c * vkp - s * vkq;
          v[k][q] = s * vkp + c * vkq;
        }
      }
    }
  }
  int best = 0;
  for (int i = 1; i < 4; ++i)
    if (a[i][i] > a[best][best]) best = i;
  return {v[0][best], v[1][best], v[2][best], v[3][best]};
}

// ATE as defined by the TUM RGB-D benchmark (Sturm et al. 2012): translation RMSE after the
// rigid transform (no scale) that best aligns the estimated positions with the ground truth in
// the least-squares sense (Horn 1987, closed form with unit quaternions).
Ate ComputeAteAligned(const std::vector<recon::Pose>& est, const std::vector<recon::Pose>& truth) {
  Ate a;
  const size_t n = est.size();
  if (n == 0) return a;
  double me[3] = {}, mg[3] = {};
  for (size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) me[c] += est[i].t[c] / n, mg[c] += truth[i].t[c] / n;
  double s[3][3] = {};  // sum (e - me)(g - mg)^T
  for (size_t i = 0; i < n; ++i)
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) s[r][c] += (est[i].t[r] - me[r]) * (truth[i].t[c] - mg[c]);
  double m[4][4] = {
      {s[0][0] + s[1][1] + s[2][2], s[1][2] - s[2][1], s[2][0] - s[0][2], s[0][1] - s[1][0]},
      {s[1][2] - s[2][1], s[0][0] - s[1][1] - s[2][2], s[0][1] + s[1][0], s[2][0] + s[0][2]},
      {s[2][0] - s[0][2], s[0][1] + s[1][0], -s[0][0] + s[1][1] - s[2][2], s[1][2] + s[2][1]},
      {s[0][1] - s[1][0], s[2][0] + s[0][2], s[1][2] + s[2][1], -s[0][0] - s[1][1] + s[2][2]}};
  const std::array<double, 4> q = LargestEigenvector(m);
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                          {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                          {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
  double sum2 = 0;
  for (size_t i = 0; i < n; ++i) {
    double e2 = 0;
    for (int row = 0; row < 3; ++row) {
      double p = mg[row];
      for (int c = 0; c < 3; ++c) p += r[row][c] * (est[i].t[c] - me[c]);
      e2 += (p - truth[i].t[row]) * (p - truth[i].t[row]);
    }
    sum2 += e2;
    a.max = std::max(a.max, std::sqrt(e2));
  }
  a.rmse = std::sqrt(sum2 / n);
  return a;
}

std::vector<Frame> LoadSevenScenes(const std::string& dir, int first, int last,
                                   recon::Intrinsics* k) {
  dataset::DatasetOptions options;
  options.max_frames = last > 0 ? static_cast<uint64_t>(last + 1) : 0;
  // "tum:" folders (fusion_eval --tum) go through the same loader: same topics, depth in mm.
  auto source = dataset::OpenDataset(dir.starts_with("tum:") ? dir : "7scenes:" + dir, options);
  std::vector<Frame> frames;
  Frame current;
  int index = 0;
  bool have_depth = false, have_pose = false, have_image = false;
  while (auto m = source->Next()) {
    const std::string& topic = source->topics()[m->topic_index].topic;
    const auto bytes = m->message.bytes();
    if (topic == "/camera/camera_info") {
      *k =
          recon::IntrinsicsFromCameraInfo(*reinterpret_cast<const msgs::CameraInfo*>(bytes.data()));
    } else if (topic == "/camera/depth") {
      recon::DepthFromImage(*reinterpret_cast<const msgs::Image*>(bytes.data()),
                            bytes.subspan(sizeof(msgs::Image)), 0.001, 0.3f, 4.0f, current.depth);
      have_depth = true;
    } else if (topic == "/camera/image") {
      recon::GreyFromImage(*reinterpret_cast<const msgs::Image*>(bytes.data()),
                           bytes.subspan(sizeof(msgs::Image)), current.grey);
      have_image = true;
    } else if (topic == "/groundtruth/pose") {
      current.truth =
          recon::Pose::FromMsg(reinterpret_cast<const msgs::Pose*>(bytes.data())->transform);
      have_pose = true;
    }
    if (have_depth && have_pose && have_image) {
      if (index >= first) frames.push_back(std::move(current));
      current = Frame{};
      have_depth = have_pose = have_image = false;
      ++index;
    }
  }
  return frames;
}

struct PeerResult {
  int frames = 0;
  double ms_median = 0;
  double cpu_ms_median = 0;
  Ate ate;
  Ate ate_aligned;
};

// OpenCV 4.6: kinfu TSDF volume + rgbd::ICPOdometry, frame to frame.
PeerResult RunOpenCvPeer(const std::vector<Frame>& frames, const recon::Intrinsics& k,
                         const recon::FusionOptions& fusion) {
  const cv::Matx33f camera(k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
  cv::Matx44f volume_pose = cv::Matx44f::eye();
  volume_pose(0, 3) = fusion.volume.origin.x;
  volume_pose(1, 3) = fusion.volume.origin.y;
  volume_pose(2, 3) = fusion.volume.origin.z;
  const int res = fusion.volume.resolution;
  cv::Ptr<cv::kinfu::Volume> volume = cv::kinfu::makeVolume(
      cv::kinfu::VolumeType::TSDF, fusion.volume.size_m / res, volume_pose, 0.25f,
      fusion.volume.truncation_m, fusion.volume.max_weight, 0.0f, cv::Vec3i(res, res, res));
  std::vector<int> iterations(fusion.icp.iterations.begin(), fusion.icp.iterations.end());
  cv::rgbd::ICPOdometry odometry(cv::Mat(camera), 0.3f, 4.0f, 0.07f, 0.07f, iterations,
                                 cv::rgbd::Odometry::RIGID_BODY_MOTION);
  const cv::kinfu::Intr intr(k.fx, k.fy, k.cx, k.cy);
  std::vector<double> ms, cpu;
  std::vector<recon::Pose> est, truth;
  cv::Matx44d pose = cv::Matx44d::eye();
  cv::Mat prev_depth;
  const cv::Mat empty;
  for (const Frame& f : frames) {
    cv::Mat depth(k.height, k.width, CV_32F, const_cast<float*>(f.depth.data.data()));
    cv::Mat depth_copy = depth.clone();
    for (int y = 0; y < depth_copy.rows; ++y)
      for (int x = 0; x < depth_copy.cols; ++x)
        if (depth_copy.at<float>(y, x) == 0) depth_copy.at<float>(y, x) = std::nanf("");
    const auto t0 = std::chrono::steady_clock::now();
    const double cpu0 = CpuMs();
    if (!prev_depth.empty()) {
      cv::Mat rt;
      if (odometry.compute(empty, depth_copy, empty, empty, prev_depth, empty, rt)) {
        pose = pose * cv::Matx44d(rt);  // rt maps current-frame points into the previous frame
      }
    }
    volume->integrate(depth, 1.0f, cv::Matx44f(pose), intr);
    cv::Mat points, normals;
    volume->raycast(cv::Matx44f(pose), intr, cv::Size(k.width, k.height), points, normals);
    ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    cpu.push_back(CpuMs() - cpu0);
    prev_depth = depth_copy;
    recon::Pose p;
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) p.r[i * 3 + j] = pose(i, j);
      p.t[i] = pose(i, 3);
    }
    est.push_back(p);
    truth.push_back(f.truth);
  }
  PeerResult r;
  r.frames = static_cast<int>(frames.size());
  r.ms_median = Median(ms);
  r.cpu_ms_median = Median(cpu);
  r.ate = ComputeAte(est, truth);
  r.ate_aligned = ComputeAteAligned(est, truth);
  return r;
}

std::pair<int, int> ParseRange(const std::string& text) {
  const size_t dash = text.find('-');
  const std::string_view all(text);
  const auto a = parse::TryParseInteger<int>(all.substr(0, dash), 0);
  const auto b = dash == std::string::npos ? std::nullopt
                                           : parse::TryParseInteger<int>(all.substr(dash + 1), 0);
  if (!a || !b || *b < *a) {
    throw UsageError("--frames expects A-B (0-based, inclusive, A <= B), got '" + text + "'");
  }
  return {*a, *b};
}

std::string Json(const std::vector<std::pair<std::string, double>>& fields) {
  std::ostringstream out;
  out.precision(6);
  out << "{\n";
  for (size_t i = 0; i < fields.size(); ++i) {
    out << "  \"" << fields[i].first << "\": " << fields[i].second
        << (i + 1 < fields.size() ? ",\n" : "\n");
  }
  out << "}\n";
  return out.str();
}

void WriteJson(const std::string& path, const std::string& json) {
  std::ofstream f(path);
  if (!f) throw UsageError("cannot write '" + path + "'");
  f << json;
  std::printf("%s", json.c_str());
}

// One line per frame: index, the estimate's 3x4 [R | t] and the ground truth's (row-major).
void WritePoses(const std::string& path, const std::vector<recon::Pose>& est,
                const std::vector<recon::Pose>& truth) {
  std::ofstream f(path);
  if (!f) throw UsageError("cannot write '" + path + "'");
  f.precision(9);
  for (size_t i = 0; i < est.size(); ++i) {
    f << i;
    for (const recon::Pose* p : {&est[i], &truth[i]})
      for (int r = 0; r < 3; ++r)
        f << ' ' << p->r[r * 3] << ' ' << p->r[r * 3 + 1] << ' ' << p->r[r * 3 + 2] << ' '
          << p->t[r];
    f << '\n';
  }
}

int RunSevenScenes(const std::string& dir, std::pair<int, int> range, bool peer, int peer_frames,
                   const std::string& json, const std::string& mesh, int threads, bool merge,
                   bool verbose, const recon::VolumeOptions* volume, float min_inliers,
                   const std::string& poses_out) {
  recon::Intrinsics k;
  std::vector<Frame> frames = LoadSevenScenes(dir, range.first, range.second, &k);
  if (const auto sc = KnobDouble("FUSION_EVAL_DEPTH_SCALE", 0)) {
    const float f = static_cast<float>(*sc);
    for (Frame& fr : frames)
      for (float& d : fr.depth.data) d *= f;
  }
  if (frames.empty()) throw UsageError("no frames in '" + dir + "'");
  if (const auto fo = KnobDouble("FUSION_EVAL_FOCAL", 1e-6)) k.fx = k.fy = static_cast<float>(*fo);
  if (const char* kd = std::getenv("FUSION_EVAL_K1")) {  // experiment: radial undistortion k1[,k2]
    const std::vector<double> ks = parse::ParseDoubleList("FUSION_EVAL_K1", kd, 1, 2);
    const float k1 = static_cast<float>(ks[0]);
    const float k2 = ks.size() > 1 ? static_cast<float>(ks[1]) : 0.0f;
    for (Frame& fr : frames) {
      recon::DepthImage out;
      out.Resize(fr.depth.width, fr.depth.height);
      for (int v = 0; v < fr.depth.height; ++v)
        for (int u = 0; u < fr.depth.width; ++u) {
          const float x = (u - k.cx) / k.fx, y = (v - k.cy) / k.fy, r2 = x * x + y * y;
          const float s = 1 + k1 * r2 + k2 * r2 * r2;
          const int ud = static_cast<int>(std::lround(k.fx * x * s + k.cx));
          const int vd = static_cast<int>(std::lround(k.fy * y * s + k.cy));
          out.data[v * out.width + u] =
              (ud >= 0 && vd >= 0 && ud < fr.depth.width && vd < fr.depth.height)
                  ? fr.depth.data[vd * fr.depth.width + ud]
                  : 0.0f;
        }
      fr.depth = std::move(out);
    }
  }
  if (const auto dm = KnobDouble("FUSION_EVAL_DEPTH_MAX", 0)) {
    const float m = static_cast<float>(*dm);
    for (Frame& fr : frames)
      for (float& d : fr.depth.data)
        if (d > m) d = 0;
  }
  recon::FusionOptions options;
  ApplyMergeKnobs(options.merge);
  options.threads = threads;
  options.merge_enabled = merge;
  if (volume) options.volume = *volume;
  if (min_inliers >= 0) options.icp.min_inlier_fraction = min_inliers;
  if (const char* it = std::getenv("FUSION_EVAL_ICP")) {
    // Was silently ignored unless exactly three integers.
    const std::vector<int> n = parse::ParseIntegerList<int>("FUSION_EVAL_ICP", it, 3, 3, 0);
    options.icp.iterations = {n[0], n[1], n[2]};
  }
  if (const auto br = KnobInt("FUSION_EVAL_BILATERAL", 0)) {
    options.preprocess.bilateral_radius = *br;
  }
  if (const auto an = KnobDouble("FUSION_EVAL_ANGLE", 0)) options.icp.max_angle_deg = *an;
  if (const auto tl = KnobInt("FUSION_EVAL_TRACK_LEVEL", 0)) options.track_level = *tl;
  if (const auto md = KnobDouble("FUSION_EVAL_MAXDIST", 0)) options.icp.max_distance_m = *md;
  if (const auto mw = KnobInt("FUSION_EVAL_MAXW", 1)) options.volume.max_weight = *mw;
  if (const auto tr = KnobDouble("FUSION_EVAL_TRUNC", 0)) options.volume.truncation_m = *tr;
  if (const char* ns = std::getenv("FUSION_EVAL_NORMALS")) {  // depth | volume (G_r normals)
    options.normal_source =
        std::string(ns) == "volume" ? recon::NormalSource::kVolume : recon::NormalSource::kDepth;
  }
  if (const char* ob = std::getenv("FUSION_EVAL_OBSERVABILITY")) {  // good,soft,hard
    recon::TrackingQualityOptions& q = options.quality;
    const std::vector<double> v = parse::ParseDoubleList("FUSION_EVAL_OBSERVABILITY", ob, 3, 3);
    q.observability_good = static_cast<float>(v[0]);
    q.observability_soft = static_cast<float>(v[1]);
    q.observability_hard = static_cast<float>(v[2]);
  }
  if (const auto nb = KnobInt("FUSION_EVAL_NORMAL_BLOCK", 0)) options.volume_normal_block = *nb;
  if (const auto mo = KnobInt("FUSION_EVAL_MATCHED_OBSERVABILITY", 0, 1)) {
    options.quality.matched_observability = *mo == 1;
  }
  recon::FusionPipeline pipeline(options);
  const recon::VolumeOptions& vol = pipeline.options().volume;
  std::fprintf(stderr,
               "fusion_eval: %zu frames, volume %d^3 over %.2f m (%.1f mm voxels) at origin "
               "(%.2f, %.2f, %.2f) of the first camera, truncation %.3f m\n",
               frames.size(), vol.resolution, vol.size_m, 1000.0 * vol.size_m / vol.resolution,
               vol.origin.x, vol.origin.y, vol.origin.z, vol.truncation_m);
  std::vector<double> total, pre, icp, integ, ray, mrg, cpu;
  std::vector<double> pre_cpu, icp_cpu, integ_cpu, ray_cpu, mrg_cpu;
  std::vector<recon::Pose> est, truth;
  int lost = 0, uncertain = 0, relocalised = 0;
  float min_observability = 1e9f, min_frame_observability = 1e9f, min_matched_observability = 1e9f,
        max_motion_m = 0, max_motion_deg = 0, max_residual_ratio = 0, min_inlier_ratio = 1e9f,
        min_score = 1;
  for (const Frame& f : frames) {
    const recon::GreyImage* grey =
        (f.grey.width == f.depth.width && f.grey.height == f.depth.height) ? &f.grey : nullptr;
    const double cpu0 = CpuMs();
    const recon::FrameResult r = pipeline.Process(f.depth, k, grey);
    cpu.push_back(CpuMs() - cpu0);
    lost += r.state == recon::TrackingState::kLost;
    uncertain += r.state == recon::TrackingState::kUncertain;
    relocalised += r.relocalised;
    if (r.icp.pairs > 0) {
      const recon::TrackingQuality& q = r.quality;
      min_score = std::min(min_score, q.score);
      min_observability = std::min(min_observability, q.observability);
      min_frame_observability = std::min(min_frame_observability, q.frame_observability);
      min_matched_observability = std::min(min_matched_observability, q.matched_observability);
      max_motion_m = std::max(max_motion_m, q.motion_translation_m);
      max_motion_deg = std::max(max_motion_deg, q.motion_rotation_deg);
      max_residual_ratio = std::max(max_residual_ratio, q.residual_ratio);
      if (q.inlier_ratio > 0) min_inlier_ratio = std::min(min_inlier_ratio, q.inlier_ratio);
    }
    if (verbose) {
      const recon::Vec3f t = r.camera_to_world.Translation();
      const recon::Pose g = frames[0].truth.Inverse() * f.truth;
      std::vector<float> d;
      for (float v : f.depth.data)
        if (v > 0) d.push_back(v);
      std::sort(d.begin(), d.end());
      const float d10 = d.empty() ? 0 : d[d.size() / 10], d50 = d.empty() ? 0 : d[d.size() / 2],
                  d90 = d.empty() ? 0 : d[d.size() * 9 / 10];
      const recon::Pose ae = frames[0].truth * r.camera_to_world;
      const double rot_err = (ae.Inverse() * f.truth).RotationAngle() * 57.2958;
      const recon::Vec3f fwd{static_cast<float>(rot_err), 0, 0};
      std::fprintf(
          stderr,
          "frame %zu: %s inliers %.3f rms %.4f pose %.3f %.3f %.3f truth %.3f %.3f %.3f "
          "fwd %.2f %.2f %.2f depth %.2f/%.2f/%.2f %s | %s score %.3f obs %.4f (frame %.4f, "
          "matched %.4f) motion %.4f m %.3f deg residual x%.2f inliers x%.2f %s\n",
          est.size(), r.state == recon::TrackingState::kLost ? "LOST" : "ok", r.icp.inlier_fraction,
          r.icp.rms_m, t.x, t.y, t.z, g.t[0], g.t[1], g.t[2], fwd.x, fwd.y, fwd.z, d10, d50, d90,
          r.icp.failure.c_str(), std::string(recon::TrackingStateName(r.state)).c_str(),
          r.quality.score, r.quality.observability, r.quality.frame_observability,
          r.quality.matched_observability, r.quality.motion_translation_m,
          r.quality.motion_rotation_deg, r.quality.residual_ratio, r.quality.inlier_ratio,
          r.quality.text.c_str());
    }
    total.push_back(r.timings.total_ms);
    pre.push_back(r.timings.preprocess_ms);
    icp.push_back(r.timings.icp_ms);
    integ.push_back(r.timings.integrate_ms);
    ray.push_back(r.timings.raycast_ms);
    mrg.push_back(r.timings.merge_ms);
    pre_cpu.push_back(r.timings.preprocess_cpu_ms);
    icp_cpu.push_back(r.timings.icp_cpu_ms);
    integ_cpu.push_back(r.timings.integrate_cpu_ms);
    ray_cpu.push_back(r.timings.raycast_cpu_ms);
    mrg_cpu.push_back(r.timings.merge_cpu_ms);
    est.push_back(r.camera_to_world);
    truth.push_back(f.truth);
  }
  const Ate ate = ComputeAte(est, truth);
  const Ate ate_aligned = ComputeAteAligned(est, truth);
  if (!poses_out.empty()) WritePoses(poses_out, est, truth);
  std::vector<std::pair<std::string, double>> fields = {
      {"frames", static_cast<double>(frames.size())},
      {"ate_rmse_m", ate.rmse},
      {"ate_max_m", ate.max},
      {"ate_aligned_rmse_m", ate_aligned.rmse},
      {"ate_aligned_max_m", ate_aligned.max},
      {"tracking_lost", static_cast<double>(lost)},
      {"tracking_uncertain", static_cast<double>(uncertain)},
      {"tracking_relocalised", static_cast<double>(relocalised)},
      // The tracking-quality cues' extremes over the tracked frames (recon/tracking_quality.h).
      {"quality_min_score", min_score},
      {"quality_min_observability", min_observability},
      {"quality_min_frame_observability", min_frame_observability},
      {"quality_min_matched_observability", min_matched_observability},
      {"quality_max_motion_m", max_motion_m},
      {"quality_max_motion_deg", max_motion_deg},
      {"quality_max_residual_ratio", max_residual_ratio},
      {"quality_min_inlier_ratio", min_inlier_ratio},
      {"ms_per_frame_median", Median(total)},
      {"ms_preprocess_median", Median(pre)},
      {"ms_icp_median", Median(icp)},
      {"ms_integrate_median", Median(integ)},
      {"ms_raycast_median", Median(ray)},
      {"ms_merge_median", Median(mrg)},
      {"threads", static_cast<double>(threads)},
      // CPU time of the process per frame (all threads): load-independent; on an idle machine
      // the wall time is about this / threads.
      {"cpu_ms_per_frame_median", Median(cpu)},
      {"cpu_ms_preprocess_median", Median(pre_cpu)},
      {"cpu_ms_icp_median", Median(icp_cpu)},
      {"cpu_ms_integrate_median", Median(integ_cpu)},
      {"cpu_ms_raycast_median", Median(ray_cpu)},
      {"cpu_ms_merge_median", Median(mrg_cpu)},
      {"volume_size_m", vol.size_m},
      {"volume_resolution", static_cast<double>(vol.resolution)},
      {"volume_origin_x", vol.origin.x},
      {"volume_origin_y", vol.origin.y},
      {"volume_origin_z", vol.origin.z},
  };
  if (!mesh.empty()) {
    const recon::Mesh m = pipeline.volume().ExtractMesh(pipeline.pool());
    recon::WritePly(m, mesh);
    fields.push_back({"mesh_triangles", static_cast<double>(m.indices.size() / 3)});
  }
  if (peer) {
    std::vector<Frame> subset(frames.begin(),
                              frames.begin() + std::min<size_t>(frames.size(), peer_frames));
    const auto t0 = std::chrono::steady_clock::now();
    const PeerResult p = RunOpenCvPeer(subset, k, options);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::vector<double> ours(total.begin(), total.begin() + subset.size());
    std::vector<double> ours_no_merge;
    for (size_t i = 0; i < subset.size(); ++i) ours_no_merge.push_back(total[i] - mrg[i]);
    fields.push_back({"peer_frames", static_cast<double>(p.frames)});
    fields.push_back({"peer_seconds", seconds});
    fields.push_back({"peer_ms_per_frame_median", p.ms_median});
    fields.push_back({"peer_ate_rmse_m", p.ate.rmse});
    fields.push_back({"peer_ate_aligned_rmse_m", p.ate_aligned.rmse});
    // Ours on the peer's frames.
    const std::vector<recon::Pose> est_same(est.begin(), est.begin() + subset.size());
    const std::vector<recon::Pose> truth_same(truth.begin(), truth.begin() + subset.size());
    fields.push_back({"ate_rmse_m_same_frames", ComputeAte(est_same, truth_same).rmse});
    fields.push_back(
        {"ate_aligned_rmse_m_same_frames", ComputeAteAligned(est_same, truth_same).rmse});
    fields.push_back({"peer_cpu_ms_per_frame_median", p.cpu_ms_median});
    std::vector<double> ours_cpu(cpu.begin(), cpu.begin() + subset.size());
    fields.push_back({"cpu_speedup_median", p.cpu_ms_median / std::max(1e-9, Median(ours_cpu))});
    fields.push_back({"ms_per_frame_median_same_frames", Median(ours)});
    fields.push_back({"speedup_median", p.ms_median / std::max(1e-9, Median(ours))});
    // Like for like: the peer does no depth merge.
    fields.push_back(
        {"speedup_median_without_merge", p.ms_median / std::max(1e-9, Median(ours_no_merge))});
  }
  WriteJson(json, Json(fields));
  return 0;
}

// Chessboard distance (pixels) of every pixel of the set {ids == id} (want_inside) or of its
// complement to the nearest pixel outside that set; 0 for pixels not in the set. Two-pass
// distance transform.
void ChessboardDistance(const std::vector<uint32_t>& ids, uint32_t id, bool want_inside, int width,
                        int height, std::vector<int>& out) {
  const int big = width + height;
  out.assign(ids.size(), 0);
  for (size_t p = 0; p < ids.size(); ++p) out[p] = ((ids[p] == id) == want_inside) ? big : 0;
  auto at = [&](int x, int y) { return out[static_cast<size_t>(y) * width + x]; };
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      int& d = out[static_cast<size_t>(y) * width + x];
      if (d == 0) continue;
      if (x > 0) d = std::min(d, at(x - 1, y) + 1);
      if (y > 0) {
        d = std::min(d, at(x, y - 1) + 1);
        if (x > 0) d = std::min(d, at(x - 1, y - 1) + 1);
        if (x + 1 < width) d = std::min(d, at(x + 1, y - 1) + 1);
      }
    }
  for (int y = height - 1; y >= 0; --y)
    for (int x = width - 1; x >= 0; --x) {
      int& d = out[static_cast<size_t>(y) * width + x];
      if (d == 0) continue;
      if (x + 1 < width) d = std::min(d, at(x + 1, y) + 1);
      if (y + 1 < height) {
        d = std::min(d, at(x, y + 1) + 1);
        if (x + 1 < width) d = std::min(d, at(x + 1, y + 1) + 1);
        if (x > 0) d = std::min(d, at(x - 1, y + 1) + 1);
      }
    }
}

int RunSim(const std::string& scenario_path, std::pair<int, int> range, const std::string& json,
           float volume_size, recon::Vec3f origin, int threads) {
  sim::Scenario scenario = sim::LoadScenario(scenario_path);
  uint32_t box_id = 0;
  for (size_t i = 0; i < scenario.objects.size(); ++i) {
    if (scenario.objects[i].name == "waved_box") {
      box_id = scenario.objects[i].id != 0 ? scenario.objects[i].id : static_cast<uint32_t>(i + 1);
    }
  }
  const int frames_total = static_cast<int>(scenario.frames);
  const int first = std::max(0, range.first);
  const int last = range.second > 0 ? std::min(range.second, frames_total - 1) : frames_total - 1;
  sim::Simulator simulator(scenario, threads);
  recon::FusionOptions options;
  ApplyMergeKnobs(options.merge);
  options.threads = threads;
  options.volume.size_m = volume_size;
  options.volume.origin = origin;
  options.volume.truncation_m = std::max(0.03f, 4 * volume_size / options.volume.resolution);
  options.preprocess.depth_max_m = static_cast<float>(scenario.sensor.depth_max_m);
  recon::FusionPipeline pipeline(options);
  // Sums over frames: absolute error and counts per source (raw D_c, volume D_v, the merge passes
  // D' and D'', and G_r = D'''), all pixels and the moving object.
  struct Acc {
    double err = 0;
    double n = 0;
    double holes = 0;
    double reference = 0;
  };
  std::map<std::string, Acc> acc;
  // Around the box silhouette: chessboard distance in pixels to the nearest pixel on the other
  // side of the silhouette, inside the box ("in1" = its outermost ring) and on the background
  // next to it ("out1"); pixels where the raw depth is valid (the same set for every source).
  struct Band {
    const char* name;
    int lo, hi;  // signed distance range: > 0 inside the box, < 0 outside
  };
  const Band bands[] = {{"out3", -3, -3}, {"out2", -2, -2},     {"out1", -1, -1},
                        {"in1", 1, 1},    {"in2", 2, 2},        {"in3", 3, 3},
                        {"in4_6", 4, 6},  {"in7up", 7, 1 << 20}};
  std::vector<double> merge_ms;
  std::vector<int> inside, outside;
  for (int i = first; i <= last; ++i) {
    const sim::SimFrame f = simulator.Render(static_cast<uint64_t>(i));
    recon::Intrinsics k;
    k.width = f.camera.width;
    k.height = f.camera.height;
    k.fx = static_cast<float>(f.camera.fx);
    k.fy = static_cast<float>(f.camera.fy);
    k.cx = static_cast<float>(f.camera.cx);
    k.cy = static_cast<float>(f.camera.cy);
    recon::Pose pose;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) pose.r[r * 3 + c] = f.camera.camera_to_world.rotation.m[r][c];
      pose.t[r] = f.camera.camera_to_world.translation[r];
    }
    recon::DepthImage depth;
    recon::DepthFromUnits(f.depth_mm.data(), k.width, k.height, k.width, 0.001,
                          options.preprocess.depth_min_m, options.preprocess.depth_max_m, depth);
    recon::GreyImage grey;
    recon::GreyFromRgb(f.rgb.data(), k.width, k.height, static_cast<size_t>(k.width) * 3, grey);
    const recon::FrameResult r = pipeline.Process(depth, k, &grey, &pose);
    merge_ms.push_back(r.timings.merge_ms);
    if (i - first < 10) continue;  // let the volume converge first
    const std::vector<uint32_t>& ids = f.render.object_ids;
    ChessboardDistance(ids, box_id, true, k.width, k.height, inside);
    ChessboardDistance(ids, box_id, false, k.width, k.height, outside);
    const recon::DepthImage* sources[5] = {&depth, &pipeline.volume_depth(),
                                           &pipeline.merged().merged, &pipeline.merged().smoothed,
                                           &pipeline.merged().denoised};
    const char* names[5] = {"raw", "volume", "merge_pass1", "merge_pass2", "merged"};
    for (size_t p = 0; p < depth.data.size(); ++p) {
      const float ref = f.render.depth_m[p];
      if (!(ref > options.preprocess.depth_min_m && ref < options.preprocess.depth_max_m)) continue;
      const bool moving = box_id != 0 && ids[p] == box_id;
      const bool raw_valid = depth.data[p] > 0;
      const int signed_distance = box_id == 0 ? 0 : moving ? inside[p] : -outside[p];
      if (raw_valid) {
        // Where D' took the volume over a valid measurement (eq. 3, case 2).
        const float dv = pipeline.volume_depth().data[p], d1 = pipeline.merged().merged.data[p];
        const bool took_volume = dv > 0 && d1 == dv && dv != depth.data[p];
        for (int region = 0; region < (moving ? 2 : 1); ++region) {
          Acc& a = acc[std::string("took_volume") + (region == 0 ? "" : "_moving")];
          a.reference += 1;
          if (took_volume) {
            a.n += 1;
            a.err += std::fabs(dv - ref);
          }
        }
      }
      for (int s = 0; s < 5; ++s) {
        const float d = sources[s]->data[p];
        // Also over the pixels where the raw depth is valid (like for like with raw).
        if (raw_valid && d > 0) {
          for (int region = 0; region < (moving ? 2 : 1); ++region) {
            Acc& a = acc[std::string(names[s]) + (region == 0 ? "" : "_moving") + "_where_raw"];
            a.err += std::fabs(d - ref);
            a.n += 1;
          }
          for (const Band& b : bands) {
            if (signed_distance >= b.lo && signed_distance <= b.hi) {
              Acc& a = acc[std::string(names[s]) + "_box_" + b.name];
              a.err += std::fabs(d - ref);
              a.n += 1;
            }
          }
        }
        for (int region = 0; region < (moving ? 2 : 1); ++region) {
          Acc& a = acc[std::string(names[s]) + (region == 0 ? "" : "_moving")];
          a.reference += 1;
          if (d > 0) {
            a.err += std::fabs(d - ref);
            a.n += 1;
          } else {
            a.holes += 1;
          }
        }
      }
    }
  }
  std::vector<std::pair<std::string, double>> fields = {
      {"frames", static_cast<double>(last - first + 1)},
      {"evaluated_frames", static_cast<double>(std::max(0, last - first + 1 - 10))},
      {"ms_merge_median", Median(merge_ms)},
  };
  for (const char* source : {"raw", "volume", "merge_pass1", "merge_pass2", "merged"}) {
    for (const char* region : {"", "_moving"}) {
      const std::string name = std::string(source) + region;
      const Acc& a = acc[name];
      fields.push_back({name + "_mean_abs_error_m", a.n > 0 ? a.err / a.n : 0});
      fields.push_back({name + "_hole_fraction", a.reference > 0 ? a.holes / a.reference : 0});
      const Acc& c = acc[name + "_where_raw"];
      fields.push_back({name + "_mean_abs_error_where_raw_valid_m", c.n > 0 ? c.err / c.n : 0});
    }
  }
  // Where D' replaced a valid measurement by D_v: fraction of the raw-valid pixels, and D_v's
  // mean abs error there.
  for (const char* region : {"", "_moving"}) {
    const Acc& a = acc[std::string("took_volume") + region];
    fields.push_back({std::string("merge_pass1") + region + "_took_volume_fraction",
                      a.reference > 0 ? a.n / a.reference : 0});
    fields.push_back({std::string("merge_pass1") + region + "_took_volume_mean_abs_error_m",
                      a.n > 0 ? a.err / a.n : 0});
  }
  // Error against the distance to the box silhouette (raw-valid pixels, same set per source).
  std::printf("box silhouette band: pixels | mean abs error cm: raw volume D' D'' D'''\n");
  for (const Band& b : bands) {
    std::printf("  %-6s %8.0f |", b.name, acc[std::string("raw_box_") + b.name].n);
    for (const char* source : {"raw", "volume", "merge_pass1", "merge_pass2", "merged"}) {
      const Acc& a = acc[std::string(source) + "_box_" + b.name];
      const double e = a.n > 0 ? a.err / a.n : 0;
      std::printf(" %7.2f", 100 * e);
      fields.push_back({std::string(source) + "_box_" + b.name + "_mean_abs_error_m", e});
    }
    fields.push_back(
        {std::string("box_") + b.name + "_pixels", acc[std::string("raw_box_") + b.name].n});
    std::printf("\n");
  }
  WriteJson(json, Json(fields));
  return 0;
}

int Run(int argc, char** argv) {
  std::string sevenscenes, sim_path, json, mesh, peer, poses_out;
  std::pair<int, int> range{0, -1};
  int peer_frames = 100, threads = 2;
  bool merge = true, verbose = false, volume_given = false;
  float min_inliers = -1;
  float volume_size = 5.0f;
  int volume_resolution = 256;
  recon::Vec3f origin{-2.5f, -0.05f, -2.5f};
  node::FlagParser flags("fusion_eval", kDescription);
  flags.Add("--sevenscenes", &sevenscenes, "DIR", "a 7-Scenes sequence folder");
  flags.AddCallback("--tum", "DIR", "a TUM RGB-D folder instead (e.g. a generated scene)",
                    [&](const std::string& dir) { sevenscenes = "tum:" + dir; });
  flags.Add("--sim", &sim_path, "SCENARIO", "a simulator scenario: the merge against ground truth");
  flags.AddCallback("--frames", "A-B", "frame range (0-based, inclusive; default: all)",
                    [&](const std::string& text) { range = ParseRange(text); });
  flags.Add("--peer", &peer, "opencv", "also run OpenCV kinfu + ICPOdometry");
  flags.Add("--peer-frames", &peer_frames, "N", "frames of the peer run", 1);
  flags.Add("--json", &json, "OUT", "the figures (required)");
  flags.Add("--mesh", &mesh, "OUT.ply", "write the volume's mesh");
  flags.Add("--poses", &poses_out, "OUT.txt", "write estimated and true poses per frame");
  flags.Add("--threads", &threads, "N", "worker threads", 0);
  flags.AddSwitch(
      "--no-merge", [&] { merge = false; }, "skip the depth merge");
  flags.Add("--verbose", &verbose, "per-frame lines");
  flags.AddCallback(
      "--volume-size", "M", "volume side in metres",
      [&](const std::string& text) {
        volume_size = static_cast<float>(parse::ParsePositiveDouble("--volume-size", text));
        volume_given = true;
      },
      "5 (7-Scenes: the library's 2)");
  flags.AddCallback(
      "--volume-origin", "X,Y,Z", "volume corner in metres",
      [&](const std::string& text) {
        const std::vector<double> v = parse::ParseDoubleList("--volume-origin", text, 3, 3);
        origin = {static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2])};
        volume_given = true;
      },
      "-2.5,-0.05,-2.5");
  flags.AddCallback(
      "--volume-resolution", "N", "voxels per side",
      [&](const std::string& text) {
        volume_resolution = parse::ParseInteger<int>("--volume-resolution", text, 1);
        volume_given = true;
      },
      std::to_string(volume_resolution));
  flags.Add("--min-inliers", &min_inliers, "F",
            "tracking-quality inlier fraction threshold (-1: the library's)", 0, 1);
  if (!flags.Parse(argc, argv)) return 0;
  if (json.empty()) throw UsageError("--json OUT is required");
  if (!peer.empty() && peer != "opencv") throw UsageError("--peer supports only 'opencv'");
  if (!sevenscenes.empty() == !sim_path.empty()) {
    throw UsageError("give exactly one of --sevenscenes DIR (or --tum DIR) and --sim SCENARIO");
  }
  recon::VolumeOptions seven_volume;
  if (volume_given) {
    seven_volume.size_m = volume_size;
    seven_volume.origin = origin;
    seven_volume.resolution = volume_resolution;
  }
  if (!sevenscenes.empty()) {
    return RunSevenScenes(sevenscenes, range, !peer.empty(), peer_frames, json, mesh, threads,
                          merge, verbose, volume_given ? &seven_volume : nullptr, min_inliers,
                          poses_out);
  }
  return RunSim(sim_path, range, json, volume_size, origin, threads);
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("fusion_eval", [&] { return Run(argc, argv); });
}
