// composite_eval: does an inserted virtual object look like a real one would in that place?
// Runs the real graph on each scene folder (player in lock-step -> fusion -> scene_light ->
// renderers in scene mode, launch/composite_eval.yaml) and compares /render/composite with the
// scene's rgb_inserted/ frames (the objects rendered as real geometry): ours (lit by /scene/light),
// oracle (the true light of truth.json) and baseline (uniform light of the image's mean radiance,
// no shadows). Reference: docs/evaluation.md, "composite_eval".
//
//   composite_eval --scenes DIR [--only NAME,...] [--mode gbuffer|depth] --json OUT [--sheets DIR]
//
// Exit: 0 done; 2 bad command line or scene folder (one line naming the file); 1 a graph failed;
// 130 after SIGINT/SIGTERM (the graph stopped, the work folder removed).
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "graph.h"
#include "probeless/dataset/source.h"
#include "probeless/eval/metrics.h"
#include "probeless/eval/scene_folder.h"
#include "probeless/msgs/image.h"
#include "probeless/node/flags.h"
#include "probeless/rectify/rectify.h"
#include "scene_prep.h"

namespace {

using namespace probeless;
namespace fs = std::filesystem;

constexpr const char* kUsage =
    "usage: composite_eval --scenes DIR [--only NAME,...] [--mode gbuffer|depth] --json OUT "
    "[--sheets DIR] [--light-param NAME:=VALUE]... [--render-param NAME:=VALUE]... [--no-focus] "
    "[--keep-work]";
constexpr int kProxyStride = 6;  // px between the scene proxy's vertices (2.5-4 cm at 2-3 m)

using node::UsageError;

// SIGINT/SIGTERM during a scene: the graph was stopped; the tool cleans up and exits 130.
struct Interrupted {};

void OnSignal(int) { composite_eval::RequestStop(); }

struct Options {
  std::string scenes, json, sheets, mode = "gbuffer";
  std::vector<std::string> only;
  std::vector<std::string> light_params;   // scene_light param overrides (NAME:=VALUE)
  std::vector<std::string> render_params;  // our renderer's param overrides (NAME:=VALUE)
  // scene_light's focus: the objects' centre, as a live graph passes its renderer's placement.
  bool focus = true;
  bool keep_work = false;  // keep the work folder (logs of every node, the MCAP sources)
};

// The options of the command line; nothing after --help (the generated usage is printed).
// Throws UsageError.
std::optional<Options> ParseOptions(int argc, char** argv) {
  Options o;
  node::FlagParser flags(
      "composite_eval",
      "does an inserted virtual object look like a real one would in that place? Runs the real\n"
      "graph on each scene folder and compares /render/composite (ours, oracle, baseline) with\n"
      "the scene's rgb_inserted/ frames (docs/evaluation.md); --scenes and --json are required.\n"
      "Exit: 0 done; 2 bad command line or scene folder; 1 a graph failed; 130 interrupted.");
  flags.Add("--scenes", &o.scenes, "DIR", "a folder of scene folders");
  flags.AddCallback("--only", "NAME,...", "only these scene folders (repeatable)",
                    [&](const std::string& text) {
                      std::stringstream list(text);
                      for (std::string name; std::getline(list, name, ',');) {
                        if (!name.empty()) o.only.push_back(name);
                      }
                    });
  flags.AddCallback(
      "--mode", "gbuffer|depth", "scene_light's input: fusion's G_r or the depth image",
      [&](const std::string& mode) {
        if (mode != "gbuffer" && mode != "depth") {
          throw UsageError("--mode: expected gbuffer or depth, got '" + mode + "'");
        }
        o.mode = mode;
      },
      o.mode);
  flags.Add("--json", &o.json, "OUT", "the figures");
  flags.Add("--sheets", &o.sheets, "DIR", "labelled contact sheets per scene");
  // NAME:=VALUE rules for a node's --ros-args -p section (no spaces or quotes: one shell word).
  const auto param_rule = [](const char* flag, std::vector<std::string>* into) {
    return [flag, into](const std::string& rule) {
      const size_t sep = rule.find(":=");
      if (sep == std::string::npos || sep == 0 ||
          rule.find_first_of(" '\"\\") != std::string::npos) {
        throw UsageError(std::string(flag) +
                         ": expected NAME:=VALUE without spaces or quotes, got '" + rule + "'");
      }
      into->push_back(rule);
    };
  };
  flags.AddCallback("--light-param", "NAME:=VALUE", "a scene_light param override (repeatable)",
                    param_rule("--light-param", &o.light_params));
  flags.AddCallback("--render-param", "NAME:=VALUE",
                    "a param override of our renderer (not the oracle's or baseline's; repeatable)",
                    param_rule("--render-param", &o.render_params));
  flags.AddSwitch(
      "--no-focus", [&] { o.focus = false; },
      "scene_light without the objects' centre as its focus");
  flags.Add("--keep-work", &o.keep_work,
            "keep the work folder (logs of every node, the MCAP sources)");
  if (!flags.Parse(argc, argv)) return std::nullopt;
  if (o.scenes.empty()) throw UsageError("--scenes DIR is required");
  if (o.json.empty()) throw UsageError("--json OUT is required");
  return o;
}

// A scene folder, validated before anything runs.
struct Scene {
  std::string name, dir;
  std::vector<eval::InsertedObject> objects;
  std::optional<eval::Truth> truth;
  std::vector<eval::RgbEntry> frames;
};

std::string MaskName(const std::string& rgb_file) {
  return fs::path(rgb_file).stem().string() + ".png";
}

Scene LoadScene(const fs::path& dir) {
  Scene s;
  s.name = dir.filename().string();
  s.dir = dir.string();
  s.objects = eval::LoadInsertion((dir / "insertion.yaml").string(), s.name + "/insertion.yaml");
  if (fs::exists(dir / "truth.json")) {
    s.truth = eval::LoadTruth((dir / "truth.json").string(), s.name + "/truth.json");
  }
  s.frames = eval::LoadRgbList((dir / "rgb.txt").string(), s.name + "/rgb.txt");
  if (s.frames.empty()) throw eval::EvalError(s.name + "/rgb.txt: no frames");
  for (const eval::RgbEntry& e : s.frames) {
    const std::string file = fs::path(e.file).filename().string();
    const std::pair<std::string, const char*> needed[] = {
        {"rgb_inserted/" + file, "the frame rendered with the objects as real geometry"},
        {"mask_object/" + MaskName(file), "8-bit mask, 255 where an object is seen"},
        {"mask_effect/" + MaskName(file), "8-bit mask, 255 where the objects change the image"}};
    for (const auto& [rel, what] : needed) {
      if (!fs::is_regular_file(dir / rel)) {
        throw eval::EvalError(s.name + "/" + rel + ": missing (expected " + what + ", one per " +
                              "rgb.txt entry: " + e.file + ")");
      }
    }
  }
  return s;
}

cv::Mat AsRectified(const cv::Mat& image, const rectify::Rectifier* rectifier);

cv::Mat ReadRgb(const std::string& path, int w, int h,
                const rectify::Rectifier* rectifier = nullptr) {
  cv::Mat bgr = cv::imread(path, cv::IMREAD_COLOR);
  if (bgr.empty()) throw eval::EvalError(path + ": cannot decode (expected an 8-bit colour image)");
  if (bgr.cols != w || bgr.rows != h) {
    throw eval::EvalError(path + ": " + std::to_string(bgr.cols) + "x" + std::to_string(bgr.rows) +
                          ", expected the camera's " + std::to_string(w) + "x" + std::to_string(h));
  }
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  return AsRectified(rgb, rectifier);
}

std::vector<uint8_t> ReadMask(const std::string& path, int w, int h,
                              const rectify::Rectifier* rectifier = nullptr) {
  cv::Mat m = cv::imread(path, cv::IMREAD_GRAYSCALE);
  if (m.empty()) throw eval::EvalError(path + ": cannot decode (expected an 8-bit mask PNG)");
  if (m.cols != w || m.rows != h) {
    throw eval::EvalError(path + ": " + std::to_string(m.cols) + "x" + std::to_string(m.rows) +
                          ", expected " + std::to_string(w) + "x" + std::to_string(h));
  }
  m = AsRectified(m, rectifier);
  return std::vector<uint8_t>(m.datastart, m.dataend);
}

// `image` (rgb8 or mono8) as the graph's nodes see it behind the rectify node: resampled by
// `rectifier` (bilinear, the node's code), unchanged without one.
cv::Mat AsRectified(const cv::Mat& image, const rectify::Rectifier* rectifier) {
  if (rectifier == nullptr || rectifier->passthrough()) return image;
  msgs::Image in;
  in.Init(static_cast<uint32_t>(image.cols), static_cast<uint32_t>(image.rows),
          image.channels() == 3 ? msgs::Encoding::kRgb8 : msgs::Encoding::kMono8);
  in.step = static_cast<uint32_t>(image.step[0]);
  cv::Mat out(image.rows, image.cols, image.type());
  msgs::Image out_header;
  rectifier->Rectify(in, std::as_bytes(std::span(image.datastart, image.dataend)), out_header,
                     std::as_writable_bytes(std::span(out.data, out.total() * out.elemSize())),
                     "frame");
  return out;
}

eval::LinearImage Linear(const cv::Mat& rgb) {
  return eval::DecodeSrgb(std::span<const uint8_t>(rgb.datastart, rgb.dataend), rgb.cols, rgb.rows);
}

eval::LinearImage Linear(const composite_eval::Rgb8& image) {
  return eval::DecodeSrgb(image.rgb, image.width, image.height);
}

// JSON text of an optional number.
std::string Num(std::optional<double> v) {
  if (!v || !std::isfinite(*v)) return "null";
  char text[32];
  std::snprintf(text, sizeof text, "%.6g", *v);
  return text;
}

std::string Quote(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    if (static_cast<unsigned char>(c) < 0x20) {
      char esc[8];
      std::snprintf(esc, sizeof esc, "\\u%04x", c);
      out += esc;
      continue;
    }
    out += c;
  }
  return out + "\"";
}

// Per-run accumulators of one scene.
struct RunMetrics {
  eval::PooledRmse object, effect;
  double mse_sum = 0;
  int frames = 0;
};

struct FrameRow {
  std::string timestamp;
  uint64_t object_pixels = 0;
  std::optional<double> rmse[3], si_rmse[3], effect[3];
  std::optional<double> direction_error;
  std::optional<msgs::ShLight> light;  // ours: the scene light the renderer used for this frame
};

struct SceneResult {
  std::string name;
  int frames = 0;
  std::map<std::string, std::optional<double>> numbers;  // the JSON's numeric keys
  std::vector<FrameRow> rows;
  std::vector<std::string> warnings;
  double seconds = 0;
};

const char* const kRuns[3] = {"ours", "oracle", "baseline"};

// One row of a sheet: a frame's truth and composites, cropped to `crop` (around the objects).
struct SheetRow {
  cv::Mat truth;
  std::array<std::optional<cv::Mat>, 3> runs;
  std::string label;
  cv::Rect crop;
};

// The region around the masks (objects and their effect), 3x their extent, at the image's aspect;
// the whole image when the masks are empty.
cv::Rect CropAround(const std::vector<uint8_t>& object, const std::vector<uint8_t>& effect, int w,
                    int h) {
  int x0 = w, y0 = h, x1 = -1, y1 = -1;
  for (int p = 0; p < w * h; ++p) {
    if (object[p] < 128 && effect[p] < 128) continue;
    x0 = std::min(x0, p % w);
    x1 = std::max(x1, p % w);
    y0 = std::min(y0, p / w);
    y1 = std::max(y1, p / w);
  }
  if (x1 < 0) return {0, 0, w, h};
  const double cx = 0.5 * (x0 + x1), cy = 0.5 * (y0 + y1);
  double half_w = std::max(1.5 * (x1 - x0 + 1), 40.0), half_h = std::max(1.5 * (y1 - y0 + 1), 30.0);
  half_w = std::max(half_w, half_h * w / h);  // the image's aspect
  half_w = std::min(half_w, 0.5 * w);
  half_h = half_w * h / w;
  const int cw = static_cast<int>(2 * half_w), ch = static_cast<int>(2 * half_h);
  const int left = std::clamp(static_cast<int>(cx - half_w), 0, w - cw);
  const int top = std::clamp(static_cast<int>(cy - half_h), 0, h - ch);
  return {left, top, cw, ch};
}

// The sheet: per row truth | ours | oracle | baseline | error (|ours - truth| x 4, jet), each tile
// the same crop around the objects, labelled.
void WriteSheet(const std::string& path, const Scene& scene, const std::vector<SheetRow>& rows_in) {
  const int tile_w = 320;
  std::vector<cv::Mat> rows;
  for (const SheetRow& r : rows_in) {
    const int tile_h = r.crop.height * tile_w / r.crop.width;
    auto tile = [&](const cv::Mat& rgb, const std::string& label) {
      cv::Mat t;
      if (rgb.empty()) {
        t = cv::Mat(tile_h, tile_w, CV_8UC3, cv::Scalar(60, 60, 60));
        cv::putText(t, "n/a", {tile_w / 2 - 20, tile_h / 2}, cv::FONT_HERSHEY_SIMPLEX, 0.8,
                    cv::Scalar(200, 200, 200), 2);
      } else {
        cv::resize(rgb(r.crop), t, {tile_w, tile_h}, 0, 0,
                   r.crop.width > tile_w ? cv::INTER_AREA : cv::INTER_NEAREST);
      }
      cv::Mat with_band(tile_h + 22, tile_w, CV_8UC3, cv::Scalar(255, 255, 255));
      t.copyTo(with_band(cv::Rect(0, 22, tile_w, tile_h)));
      cv::putText(with_band, label, {4, 16}, cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(0, 0, 0),
                  1);
      return with_band;
    };
    std::vector<cv::Mat> tiles;
    tiles.push_back(tile(r.truth, "truth " + r.label));
    for (int k = 0; k < 3; ++k) tiles.push_back(tile(r.runs[k] ? *r.runs[k] : cv::Mat(), kRuns[k]));
    cv::Mat error;
    if (r.runs[0]) {
      cv::Mat diff, grey;
      cv::absdiff(*r.runs[0], r.truth, diff);
      cv::cvtColor(diff, grey, cv::COLOR_RGB2GRAY);
      grey.convertTo(grey, CV_8U, 4.0);
      cv::applyColorMap(grey, error, cv::COLORMAP_JET);
      cv::cvtColor(error, error, cv::COLOR_BGR2RGB);
    }
    tiles.push_back(tile(error, "error |ours - truth| x4"));
    cv::Mat row;
    cv::hconcat(tiles, row);
    rows.push_back(row);
  }
  cv::Mat sheet;
  cv::vconcat(rows, sheet);
  cv::Mat title(28, sheet.cols, CV_8UC3, cv::Scalar(255, 255, 255));
  cv::putText(title, "composite_eval: " + scene.name + " (crops around the inserted objects)",
              {6, 20}, cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(0, 0, 0), 1);
  cv::vconcat(title, sheet, sheet);
  cv::cvtColor(sheet, sheet, cv::COLOR_RGB2BGR);
  if (!cv::imwrite(path, sheet)) throw eval::EvalError("cannot write sheet " + path);
}

std::string ExecutableDir() {
  std::error_code error;
  const fs::path self = fs::read_symlink("/proc/self/exe", error);
  return error ? "." : self.parent_path().string();
}

std::string FindLaunchFile(const std::string& bin_dir) {
  const std::vector<fs::path> candidates = {
      fs::path(PROBELESS_SOURCE_TREE) / "launch/composite_eval.yaml",
      fs::path(bin_dir) / "../../launch/composite_eval.yaml"};
  for (const fs::path& p : candidates) {
    if (fs::is_regular_file(p)) return fs::weakly_canonical(p).string();
  }
  throw std::runtime_error("launch/composite_eval.yaml not found (looked in " +
                           candidates[0].string() + ")");
}

std::string FlowList(const std::vector<std::string>& items) {
  std::string s = "[";
  for (size_t i = 0; i < items.size(); ++i) s += (i ? ", " : "") + items[i];
  return s + "]";
}

std::string Fixed(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.4f", v);
  return text;
}

SceneResult EvaluateScene(const Scene& scene, size_t k, size_t n, const Options& options,
                          const fs::path& work, const std::string& bin_dir,
                          const std::string& launch_file) {
  const auto start = std::chrono::steady_clock::now();
  SceneResult result;
  result.name = scene.name;
  result.frames = static_cast<int>(scene.frames.size());
  const std::string tag = "composite_eval: scene " + std::to_string(k + 1) + "/" +
                          std::to_string(n) + " '" + scene.name + "'";
  std::cerr << tag << ": " << scene.frames.size() << " frames, " << scene.objects.size()
            << " objects, converting\n";
  const fs::path dir = work / ("scene_" + std::to_string(k));
  fs::create_directories(dir);
  const bool depth_mode = options.mode == "depth";
  composite_eval::SceneInfo info = composite_eval::WriteSceneLog(
      scene.dir, scene.truth ? &*scene.truth : nullptr, depth_mode, (dir / "scene.mcap").string());
  // A distorted camera: the graph works behind the rectify node, and so does the comparison.
  std::optional<rectify::Rectifier> rectifier;
  if (rectify::HasDistortion(info.camera_info)) {
    rectifier.emplace(info.camera_info, rectify::RectifyOptions{}, scene.name + " camera_info");
    std::cerr << tag << ": lens distortion: evaluating in the rectified camera\n";
  }
  const rectify::Rectifier* rect = rectifier ? &*rectifier : nullptr;
  composite_eval::SetCamera(info, rect);
  const composite_eval::Rigid fusion_from_truth =
      composite_eval::FusionWorldFromTruthWorld(info, scene.name);
  std::vector<std::string> object_files;
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    const std::string file = (dir / ("object_" + std::to_string(i) + ".obj")).string();
    composite_eval::WriteObjectObj(scene.objects[i], fusion_from_truth, file);
    object_files.push_back(file);
    if (!composite_eval::VisibleInSomeFrame(info, scene.objects[i])) {
      const std::string warning =
          "objects[" + std::to_string(i) + "] (" +
          (scene.objects[i].shape == eval::Shape::kSphere ? "sphere" : "box") + ") of scene '" +
          scene.name + "' is outside every view";
      std::cerr << "composite_eval: warning: " << warning << "\n";
      result.warnings.push_back(warning);
    }
  }
  const std::string proxy = (dir / "scene_proxy.obj").string();
  composite_eval::WriteDepthProxyObj(info, kProxyStride, proxy);
  const composite_eval::VolumeParams volume =
      composite_eval::ChooseVolume(info, scene.objects, fusion_from_truth);

  composite_eval::GraphArgs graph;
  graph.probeless = bin_dir + "/probeless";
  graph.launch_file = launch_file;
  graph.domain = "ce" + std::to_string(::getpid()) + "_" + std::to_string(k);
  graph.log_path = (dir / "launch.log").string();
  graph.timeout_s = 120 + 20.0 * static_cast<double>(scene.frames.size());
  const bool oracle = info.oracle_lights > 0;
  graph.launch_args = {"source:=" + (dir / "scene.mcap").string(),
                       "mode:=" + options.mode,
                       std::string("late_depth:=") + (depth_mode ? "true" : "false"),
                       "depth_topic:=" + std::string(depth_mode ? "/composite_eval/depth_rect"
                                                                : "/camera/depth_rect"),
                       "objects:=" + FlowList(object_files),
                       "scene_mesh:=" + proxy,
                       std::string("oracle:=") + (oracle ? "true" : "false"),
                       "volume_size:=" + Fixed(volume.size),
                       "volume_origin:=[" + Fixed(volume.origin[0]) + ", " +
                           Fixed(volume.origin[1]) + ", " + Fixed(volume.origin[2]) + "]",
                       "truncation:=" + Fixed(volume.truncation),
                       "depth_max:=" + Fixed(volume.depth_max)};
  std::vector<std::string> light_params = options.light_params;
  if (options.focus && !scene.objects.empty()) {
    // The mean of the objects' centres in fusion's world (the frame of /scene/pose).
    std::array<double, 3> centre = {0, 0, 0};
    for (const eval::InsertedObject& object : scene.objects) {
      const std::array<double, 3> p = fusion_from_truth.Apply(object.position);
      for (int c = 0; c < 3; ++c) centre[c] += p[c] / static_cast<double>(scene.objects.size());
    }
    light_params.insert(light_params.begin(), "focus:=[" + Fixed(centre[0]) + "," +
                                                  Fixed(centre[1]) + "," + Fixed(centre[2]) + "]");
  }
  if (!light_params.empty()) {  // node args: a --ros-args section before the launch's own
    std::string light_args = "light_args:=--ros-args";
    for (const std::string& rule : light_params) light_args += " -p " + rule;
    graph.launch_args.push_back(light_args + " --");
  }
  if (!options.render_params.empty()) {
    std::string render_args = "render_args:=--ros-args";
    for (const std::string& rule : options.render_params) render_args += " -p " + rule;
    graph.launch_args.push_back(render_args + " --");
  }
  ::setenv("PROBELESS_LOG_DIR", (dir / "log").string().c_str(), 1);
  std::cerr << tag << ": running the graph (fusion volume " << Fixed(volume.size) << " m)\n";
  const composite_eval::GraphOutput out = composite_eval::RunGraph(graph, [&](size_t done) {
    std::cerr << tag << ": frame " << done << "/" << scene.frames.size() << "\n";
  });
  if (out.interrupted) throw Interrupted();
  if (out.exit_code != 0 || out.timed_out) {
    std::ifstream log(graph.log_path);
    std::vector<std::string> lines;
    for (std::string line; std::getline(log, line);) lines.push_back(line);
    for (size_t i = lines.size() > 15 ? lines.size() - 15 : 0; i < lines.size(); ++i) {
      std::cerr << "  | " << lines[i] << "\n";
    }
    throw std::runtime_error(scene.name + ": the graph " +
                             (out.timed_out
                                  ? std::string("timed out")
                                  : "failed (exit " + std::to_string(out.exit_code) + ")") +
                             "; its log: " + graph.log_path);
  }

  // Metrics per frame.
  RunMetrics runs[3];
  std::vector<double> direction_errors;
  int frames_with_estimate = 0;
  const std::map<int64_t, composite_eval::Rgb8>* outputs[3] = {&out.ours, &out.oracle,
                                                               &out.baseline};
  struct SheetCandidate {
    size_t frame;
    uint64_t pixels;
  };
  std::vector<SheetCandidate> candidates;
  for (size_t f = 0; f < scene.frames.size(); ++f) {
    const eval::RgbEntry& e = scene.frames[f];
    const std::string file = fs::path(e.file).filename().string();
    const int w = info.width, h = info.height;
    const cv::Mat original_rgb = ReadRgb(scene.dir + "/" + e.file, w, h, rect);
    const cv::Mat inserted_rgb = ReadRgb(scene.dir + "/rgb_inserted/" + file, w, h, rect);
    const std::vector<uint8_t> mask_object =
        ReadMask(scene.dir + "/mask_object/" + MaskName(file), w, h, rect);
    const std::vector<uint8_t> mask_effect =
        ReadMask(scene.dir + "/mask_effect/" + MaskName(file), w, h, rect);
    const eval::LinearImage original = Linear(original_rgb), inserted = Linear(inserted_rgb);
    FrameRow row;
    row.timestamp = e.timestamp;
    row.object_pixels = static_cast<uint64_t>(
        std::count_if(mask_object.begin(), mask_object.end(), [](uint8_t m) { return m >= 128; }));
    candidates.push_back({f, row.object_pixels});
    for (int r = 0; r < 3; ++r) {
      const auto it = outputs[r]->find(e.stamp_ns);
      if (it == outputs[r]->end()) continue;
      if (it->second.width != w || it->second.height != h) continue;
      const eval::LinearImage composite = Linear(it->second);
      const eval::MaskedSums object = eval::ObjectSums(composite, inserted, mask_object);
      const eval::MaskedSums effect = eval::EffectSums(composite, original, inserted, mask_effect);
      runs[r].object.Add(object);
      runs[r].effect.Add(effect);
      runs[r].mse_sum += eval::MeanSquaredError(composite, inserted);
      ++runs[r].frames;
      if (object.count > 0) {
        row.rmse[r] = std::sqrt(object.sum_sq / object.count);
        row.si_rmse[r] = std::sqrt(object.si_sum_sq / object.count);
      }
      if (effect.count > 0) row.effect[r] = std::sqrt(effect.sum_sq / effect.count);
    }
    if (out.ours.count(e.stamp_ns)) ++frames_with_estimate;
    const eval::TruthFrame* truth = scene.truth ? scene.truth->Find(e.stamp_ns) : nullptr;
    const auto light = out.lights.find(e.stamp_ns);
    if (light != out.lights.end()) row.light = light->second;
    if (truth != nullptr && truth->direction_camera && truth->direct_to_ambient >= 1 &&
        light != out.lights.end()) {
      row.direction_error =
          eval::AngleDeg(light->second.dominant_direction, truth->direction_camera->data());
      if (row.direction_error) direction_errors.push_back(*row.direction_error);
    }
    result.rows.push_back(row);
  }
  for (int r = 0; r < 3; ++r) {
    const std::string run = kRuns[r];
    const bool skipped = r == 1 && !oracle;
    result.numbers[run + "_rmse_object"] = skipped ? std::nullopt : runs[r].object.Rmse();
    result.numbers[run + "_si_rmse_object"] = skipped ? std::nullopt : runs[r].object.SiRmse();
    result.numbers[run + "_rmse_effect"] = skipped ? std::nullopt : runs[r].effect.Rmse();
    result.numbers[run + "_psnr_db"] =
        runs[r].frames > 0 && !skipped
            ? std::optional<double>(eval::PsnrDb(runs[r].mse_sum / runs[r].frames))
            : std::nullopt;
    result.numbers[run + "_frames"] = runs[r].frames;
  }
  result.numbers["direction_error_deg_median"] = eval::Median(direction_errors);
  result.numbers["direction_error_deg_p90"] = eval::Percentile(direction_errors, 0.9);
  result.numbers["direction_frames"] = static_cast<double>(direction_errors.size());
  result.numbers["frames_with_estimate"] = frames_with_estimate;

  if (!options.sheets.empty()) {
    // The frames that show the objects most (up to 3, in time order).
    std::stable_sort(
        candidates.begin(), candidates.end(),
        [](const SheetCandidate& a, const SheetCandidate& b) { return a.pixels > b.pixels; });
    if (candidates.size() > 3) candidates.resize(3);
    std::sort(candidates.begin(), candidates.end(),
              [](const SheetCandidate& a, const SheetCandidate& b) { return a.frame < b.frame; });
    std::vector<SheetRow> rows;
    for (const SheetCandidate& c : candidates) {
      const eval::RgbEntry& e = scene.frames[c.frame];
      const std::string file = fs::path(e.file).filename().string();
      SheetRow row;
      row.truth = ReadRgb(scene.dir + "/rgb_inserted/" + file, info.width, info.height, rect);
      row.crop = CropAround(
          ReadMask(scene.dir + "/mask_object/" + MaskName(file), info.width, info.height, rect),
          ReadMask(scene.dir + "/mask_effect/" + MaskName(file), info.width, info.height, rect),
          info.width, info.height);
      for (int r = 0; r < 3; ++r) {
        const auto it = outputs[r]->find(e.stamp_ns);
        if (it == outputs[r]->end()) continue;
        row.runs[r] = cv::Mat(it->second.height, it->second.width, CV_8UC3,
                              const_cast<uint8_t*>(it->second.rgb.data()))
                          .clone();
      }
      row.label = "frame " + std::to_string(c.frame + 1);
      rows.push_back(std::move(row));
    }
    fs::create_directories(options.sheets);
    WriteSheet((fs::path(options.sheets) / (scene.name + ".png")).string(), scene, rows);
  }
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::cerr << tag << ": done in " << Fixed(result.seconds) << " s (ours si-rmse "
            << Num(result.numbers["ours_si_rmse_object"]) << ", oracle "
            << Num(result.numbers["oracle_si_rmse_object"]) << ", baseline "
            << Num(result.numbers["baseline_si_rmse_object"]) << ")\n";
  return result;
}

void WriteJson(const std::string& path, const Options& options,
               const std::vector<SceneResult>& results, const std::vector<std::string>& failed) {
  std::ostringstream j;
  j << "{\n  \"tool\": \"composite_eval\",\n  \"mode\": " << Quote(options.mode) << ",\n";
  j << "  \"failed_scenes\": [";
  for (size_t f = 0; f < failed.size(); ++f) j << (f ? ", " : "") << Quote(failed[f]);
  j << "],\n  \"scenes\": [\n";
  for (size_t s = 0; s < results.size(); ++s) {
    const SceneResult& r = results[s];
    j << "    {\"name\": " << Quote(r.name) << ", \"frames\": " << r.frames;
    for (const auto& [key, value] : r.numbers) j << ", " << Quote(key) << ": " << Num(value);
    j << ", \"seconds\": " << Num(r.seconds) << ",\n     \"warnings\": [";
    for (size_t w = 0; w < r.warnings.size(); ++w) j << (w ? ", " : "") << Quote(r.warnings[w]);
    j << "],\n     \"per_frame\": [";
    for (size_t f = 0; f < r.rows.size(); ++f) {
      const FrameRow& row = r.rows[f];
      j << (f ? ",\n       " : "\n       ") << "{\"timestamp\": " << Quote(row.timestamp)
        << ", \"object_pixels\": " << row.object_pixels;
      for (int k = 0; k < 3; ++k) {
        j << ", \"" << kRuns[k] << "_rmse_object\": " << Num(row.rmse[k]) << ", \"" << kRuns[k]
          << "_si_rmse_object\": " << Num(row.si_rmse[k]) << ", \"" << kRuns[k]
          << "_rmse_effect\": " << Num(row.effect[k]);
      }
      j << ", \"direction_error_deg\": " << Num(row.direction_error);
      if (row.light) {  // diagnostics: what ours was given (camera frame, msgs SH convention)
        const msgs::ShLight& l = *row.light;
        j << ", \"ours_light\": {\"confidence\": " << Num(l.confidence)
          << ", \"dominant_direction\": [" << Num(l.dominant_direction[0]) << ", "
          << Num(l.dominant_direction[1]) << ", " << Num(l.dominant_direction[2]) << "], \"sh\": [";
        for (uint32_t k = 0; k < l.CoefficientCount(); ++k) {
          j << (k ? ", [" : "[") << Num(l.coefficients[k][0]) << ", " << Num(l.coefficients[k][1])
            << ", " << Num(l.coefficients[k][2]) << "]";
        }
        j << "]}";
      }
      j << "}";
    }
    j << "]}" << (s + 1 < results.size() ? "," : "") << "\n";
  }
  j << "  ],\n  \"summary\": {\n    \"scene_count\": " << results.size();
  std::map<std::string, std::vector<double>> columns;
  for (const SceneResult& r : results) {
    for (const auto& [key, value] : r.numbers) {
      columns[key];
      if (value && std::isfinite(*value)) columns[key].push_back(*value);
    }
  }
  for (const auto& [key, values] : columns) {
    j << ",\n    " << Quote(key) << ": {\"median\": " << Num(eval::Median(values))
      << ", \"p90\": " << Num(eval::Percentile(values, 0.9)) << ", \"count\": " << values.size()
      << "}";
  }
  j << "\n  }\n}\n";
  std::ofstream file(path);
  file << j.str();
  if (!file) throw std::runtime_error("cannot write " + path);
}

int Run(int argc, char** argv) {
  Options options;
  try {
    const std::optional<Options> parsed = ParseOptions(argc, argv);
    if (!parsed) return 0;
    options = *parsed;
  } catch (const UsageError& e) {
    std::cerr << "composite_eval: " << e.what() << "\n" << kUsage << "\n";
    return 2;
  }
  std::vector<Scene> scenes;
  try {
    if (!fs::is_directory(options.scenes)) {
      throw eval::EvalError(options.scenes + ": not a folder (expected a folder of scene folders)");
    }
    std::vector<fs::path> dirs;
    for (const auto& entry : fs::directory_iterator(options.scenes)) {
      if (entry.is_directory() && fs::exists(entry.path() / "rgb.txt"))
        dirs.push_back(entry.path());
    }
    std::sort(dirs.begin(), dirs.end());
    for (const std::string& name : options.only) {
      if (std::none_of(dirs.begin(), dirs.end(),
                       [&](const fs::path& d) { return d.filename() == name; })) {
        throw eval::EvalError("--only: no scene folder '" + name + "' in " + options.scenes);
      }
    }
    for (const fs::path& d : dirs) {
      if (!options.only.empty() && std::find(options.only.begin(), options.only.end(),
                                             d.filename().string()) == options.only.end()) {
        continue;
      }
      scenes.push_back(LoadScene(d));
    }
    if (scenes.empty()) {
      throw eval::EvalError(options.scenes +
                            ": no scene folders (expected sub-folders with rgb.txt)");
    }
  } catch (const eval::EvalError& e) {
    std::cerr << "composite_eval: " << e.what() << "\n";
    return 2;
  }
  const std::string bin_dir = ExecutableDir();
  const std::string launch_file = FindLaunchFile(bin_dir);
  const fs::path work =
      fs::temp_directory_path() / ("composite_eval." + std::to_string(::getpid()));
  fs::remove_all(work);
  fs::create_directories(work);
  std::vector<SceneResult> results;
  int exit_code = 0;
  struct sigaction action = {};
  action.sa_handler = OnSignal;
  ::sigaction(SIGINT, &action, nullptr);
  ::sigaction(SIGTERM, &action, nullptr);
  // A scene that fails is reported and skipped: the other scenes' results are still written.
  std::vector<std::string> failed;
  bool keep_work = options.keep_work;
  if (keep_work) std::cerr << "composite_eval: work folder " << work.string() << " (kept)\n";
  for (size_t k = 0; k < scenes.size(); ++k) {
    if (composite_eval::StopRequested()) {
      std::cerr << "composite_eval: interrupted\n";
      fs::remove_all(work);
      return 130;
    }
    try {
      results.push_back(
          EvaluateScene(scenes[k], k, scenes.size(), options, work, bin_dir, launch_file));
    } catch (const Interrupted&) {
      std::cerr << "composite_eval: interrupted\n";
      fs::remove_all(work);
      return 130;
    } catch (const eval::EvalError& e) {
      std::cerr << "composite_eval: " << e.what() << "\n";
      failed.push_back(e.what());
      exit_code = std::max(exit_code, 2);
    } catch (const dataset::DatasetError& e) {
      std::cerr << "composite_eval: " << e.what() << "\n";
      failed.push_back(e.what());
      exit_code = std::max(exit_code, 2);
    } catch (const rectify::RectifyError& e) {
      std::cerr << "composite_eval: " << e.what() << "\n";
      failed.push_back(e.what());
      exit_code = std::max(exit_code, 2);
    } catch (const std::exception& e) {
      std::cerr << "composite_eval: " << e.what() << " (work folder kept: " << work.string()
                << ")\n";
      failed.push_back(e.what());
      exit_code = exit_code == 0 ? 1 : exit_code;
      keep_work = true;
    }
  }
  if (results.empty()) {
    if (!keep_work) fs::remove_all(work);
    return exit_code;
  }
  WriteJson(options.json, options, results, failed);
  if (!keep_work) fs::remove_all(work);
  std::cerr << "composite_eval: " << results.size() << " scenes -> " << options.json;
  if (!failed.empty()) std::cerr << " (" << failed.size() << " failed, listed in the JSON)";
  std::cerr << "\n";
  return exit_code;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "composite_eval: " << e.what() << "\n";
    return 1;
  }
}
