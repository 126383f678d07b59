#include "offline.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <vector>

#include "probeless/node/main.h"

namespace probeless::sim_node {

// Progress lines at most once a second (and at the end): "frame k/N, x fps".
std::function<void(uint64_t, uint64_t)> ProgressPrinter(const std::string& what,
                                                        const std::string& unit) {
  auto start =
      std::make_shared<std::chrono::steady_clock::time_point>(std::chrono::steady_clock::now());
  auto last = std::make_shared<std::chrono::steady_clock::time_point>(*start);
  return [=](uint64_t done, uint64_t total) {
    const auto now = std::chrono::steady_clock::now();
    if (done != total && now - *last < std::chrono::seconds(1)) return;
    *last = now;
    const double s = std::chrono::duration<double>(now - *start).count();
    std::fprintf(stderr, "[info] [sim] %s: %s %llu/%llu (%.1f %s/s)\n", what.c_str(), unit.c_str(),
                 static_cast<unsigned long long>(done), static_cast<unsigned long long>(total),
                 s > 0 ? done / s : 0.0, unit == "frame" ? "frames" : (unit + "s").c_str());
  };
}

// A contact sheet: up to 8 frames evenly spread over the scenario, RGB above a colour-mapped depth.
void WritePreview(sim::Scenario scenario, uint64_t frames, int threads, const std::string& path) {
  sim::Simulator simulator(std::move(scenario), threads);
  const uint64_t n = std::min<uint64_t>(8, frames);
  const int w = simulator.scenario().camera.width;
  const int h = simulator.scenario().camera.height;
  const int tile_w = std::min(w, 320);
  const int tile_h = h * tile_w / w;
  const int columns = static_cast<int>(std::min<uint64_t>(4, n));
  const int rows = static_cast<int>((n + columns - 1) / columns);
  cv::Mat sheet(rows * tile_h * 2, columns * tile_w, CV_8UC3, cv::Scalar(0, 0, 0));
  auto progress = ProgressPrinter("preview");
  for (uint64_t k = 0; k < n; ++k) {
    const uint64_t index = n == 1 ? 0 : k * (frames - 1) / (n - 1);
    const sim::SimFrame f = simulator.Render(index);
    cv::Mat rgb(h, w, CV_8UC3, const_cast<uint8_t*>(f.rgb.data()));
    cv::Mat bgr;
    cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
    cv::Mat depth(h, w, CV_16UC1, const_cast<uint16_t*>(f.depth_mm.data()));
    cv::Mat depth8;
    depth.convertTo(depth8, CV_8UC1, 255.0 / 5000.0);
    cv::Mat depth_color;
    cv::applyColorMap(depth8, depth_color, cv::COLORMAP_TURBO);
    depth_color.setTo(cv::Scalar(0, 0, 0), depth == 0);
    const int x = static_cast<int>(k % columns) * tile_w;
    const int y = static_cast<int>(k / columns) * tile_h * 2;
    cv::resize(bgr, sheet(cv::Rect(x, y, tile_w, tile_h)), cv::Size(tile_w, tile_h), 0, 0,
               cv::INTER_AREA);
    cv::resize(depth_color, sheet(cv::Rect(x, y + tile_h, tile_w, tile_h)),
               cv::Size(tile_w, tile_h), 0, 0, cv::INTER_NEAREST);
    cv::putText(sheet, "frame " + std::to_string(index), cv::Point(x + 6, y + 18),
                cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1);
    progress(k + 1, n);
  }
  if (!cv::imwrite(path, sheet)) throw std::runtime_error("cannot write preview '" + path + "'");
  std::printf("sim: wrote %s (%llu frames)\n", path.c_str(), static_cast<unsigned long long>(n));
}

// sim --yaleb-style: the ICT mesh and the light list from the shared data when present.
int WriteYaleBStyle(const std::string& out_dir, sim::YaleBStyleOptions options) {
  if (options.mesh == "ict") {
    const auto ict = sim::FindDataFile("meshes/ict_generic_neutral_mesh.obj");
    if (!ict) {
      throw node::UsageError(
          "--mesh ict: meshes/ict_generic_neutral_mesh.obj not found in $PROBELESS_DATA or the "
          "shared data folder");
    }
    options.ict_path = *ict;
  } else if (options.mesh != "procedural") {
    throw node::UsageError("--mesh: expected 'procedural' or 'ict', got '" + options.mesh + "'");
  }
  std::string light_source = "built-in Yale B table";
  if (const auto first = sim::FindDataFile("yaleb/yaleB01/yaleB01_P00A+000E+00.pgm")) {
    std::vector<sim::YaleBLightDirection> lights =
        sim::YaleBLightDirectionsFromFolder(std::filesystem::path(*first).parent_path().string());
    if (lights.size() == 64) {
      light_source = "file names of " + std::filesystem::path(*first).parent_path().string();
      if (options.behind) {
        for (const auto& l : sim::BehindLightDirections()) lights.push_back(l);
      }
      options.lights = std::move(lights);
    }
  }
  try {
    options.Validate();
  } catch (const sim::ScenarioError& error) {
    throw node::UsageError(error.what());
  }
  std::fprintf(stderr, "[info] [sim] yaleb-style: %d subjects, %dx%d, mesh %s, lights from %s\n",
               options.subjects, options.width, options.height, options.mesh.c_str(),
               light_source.c_str());
  options.progress = ProgressPrinter("yaleb-style " + out_dir, "image");
  const auto start = std::chrono::steady_clock::now();
  const sim::YaleBStyleSummary summary = sim::WriteYaleBStyleDataset(out_dir, options);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "sim: wrote %llu images of %d subjects to %s in %.1f s (alignment error <= %.2f px)\n",
      static_cast<unsigned long long>(summary.images), summary.subjects, out_dir.c_str(), s,
      summary.max_alignment_error_px);
  return 0;
}

// sim --generate: N scenes of a split, one after the other, each on every render thread.
int Generate(int count, uint64_t seed, const std::string& split_name, const std::string& out_dir,
             sim::GenerateOptions options, bool resume) {
  const sim::Split split = sim::ParseSplit(split_name);
  if (count < 1) throw node::UsageError("--generate: expected a scene count >= 1");
  if (out_dir.empty()) throw node::UsageError("--generate needs --out DIR");
  if (seed + static_cast<uint64_t>(count) > sim::kSplitSeedStride) {
    throw node::UsageError("--seed + --generate must stay below " +
                           std::to_string(sim::kSplitSeedStride) + " (disjoint split ranges)");
  }
  options.Validate();
  const auto start = std::chrono::steady_clock::now();
  auto last = start;
  int written = 0, skipped = 0;
  options.progress = [&](int scene, int frame, int frames) {
    const auto now = std::chrono::steady_clock::now();
    if (frame != frames && now - last < std::chrono::seconds(2)) return;
    last = now;
    std::fprintf(stderr, "[info] [sim] generate: scene %d/%d, frame %d/%d (%.0f s)\n", scene + 1,
                 count, frame, frames, std::chrono::duration<double>(now - start).count());
  };
  for (int k = 0; k < count; ++k) {
    const uint64_t scene_seed = sim::SplitSeedBase(split) + seed + static_cast<uint64_t>(k);
    const sim::GeneratedScene scene = sim::GenerateScene(scene_seed, split, options);
    if (resume &&
        std::filesystem::exists(std::filesystem::path(out_dir) / scene.name / "scene.json")) {
      ++skipped;
      continue;
    }
    const sim::GeneratedSceneSummary summary = sim::WriteGeneratedScene(scene, options, out_dir, k);
    ++written;
    std::fprintf(stderr,
                 "[info] [sim] generate: %s (%s, %s, object seen in %d/%d frames) in %.1f s\n",
                 summary.folder.c_str(), scene.room.c_str(), scene.light_type.c_str(),
                 summary.frames_object_visible, summary.frames, summary.seconds);
  }
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("sim: wrote %d %s scenes (%d already complete) to %s in %.1f s\n", written,
              split_name.c_str(), skipped, out_dir.c_str(), s);
  return 0;
}

}  // namespace probeless::sim_node
