// raytrace_bench: speed of the ray tracer and the simulator.
//
//   raytrace_bench [--scenario FILE.yaml] [--frames N] [--threads N] [--json OUT]
//                  [--pt-spp N] [--pt-image OUT.ppm] [--no-pt] [--pt-only]
//                  [--pt-size WxH] [--pt-seed S] [--pt-rr N] [--pt-raw OUT.pfm] [--pt-ref REF.pfm]
//
// Rows: (1) whole simulator frames (render + sensor effects + ground truth) of the scenario,
// default data/scenarios/room_dynamic.yaml at its 640x480 with shadows; (2) the renderer alone on
// the same frames; (3) batched closest-hit and (4) occlusion queries of random rays through the
// scene (the PRT-bake API); (5) one path-traced 640x480 frame of the furnished room of
// pathtrace_room.h (64 paths per pixel, 3 bounces, sun + sky + 2 lamps). Prints a table; --json
// writes the same figures. Noise of the path trace: --pt-raw writes its linear RGB (PFM), --pt-ref
// prints its rms error per pixel and channel against a reference PFM (a high-spp render), divided
// by the reference's mean; --pt-size renders the room smaller (the same view), --pt-only skips rows
// 1-4.
#include "probeless/node/main.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "pathtrace_room.h"
#include "probeless/node/flags.h"
#include "probeless/parse/number.h"
#include "probeless/raytrace/pathtrace.h"
#include "probeless/raytrace/render.h"
#include "probeless/sim/simulator.h"

namespace {

using namespace probeless;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

struct Row {
  std::string name;
  double seconds = 0;
  double frames = 0;  // 0 for ray-only rows
  double rays = 0;
  double cpu_seconds = -1;  // process CPU time (all threads), when measured
};

// Process CPU time of all threads: with wall time it shows how much other load slowed a row.
double CpuSeconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

// The machine's 1-minute load average (-1 if unknown): the figures are only comparable when low.
double LoadAverage() {
  double load[1];
  return getloadavg(load, 1) == 1 ? load[0] : -1;
}

// Writes 8-bit sRGB as a binary PPM.
void WritePpm(const std::string& path, const raytrace::Frame& f) {
  std::ofstream out(path, std::ios::binary);
  out << "P6\n" << f.width << " " << f.height << "\n255\n";
  out.write(reinterpret_cast<const char*>(f.srgb.data()),
            static_cast<std::streamsize>(f.srgb.size()));
  if (!out) throw std::runtime_error("cannot write '" + path + "'");
}

// Writes linear RGB as a little-endian PFM (bottom row first).
void WritePfm(const std::string& path, const raytrace::Frame& f) {
  std::ofstream out(path, std::ios::binary);
  out << "PF\n" << f.width << " " << f.height << "\n-1.0\n";
  for (int y = f.height - 1; y >= 0; --y) {
    out.write(reinterpret_cast<const char*>(&f.linear_rgb[3 * static_cast<size_t>(y) * f.width]),
              static_cast<std::streamsize>(3 * sizeof(float) * f.width));
  }
  if (!out) throw std::runtime_error("cannot write '" + path + "'");
}

// Reads a PFM written by WritePfm into top-row-first linear RGB of width x height.
std::vector<float> ReadPfm(const std::string& path, int width, int height) {
  std::ifstream in(path, std::ios::binary);
  std::string magic;
  int w = 0, h = 0;
  double scale = 0;
  in >> magic >> w >> h >> scale;
  in.get();
  if (!in || magic != "PF" || w != width || h != height || scale >= 0) {
    throw InputError("'" + path + "': not a little-endian RGB PFM of " + std::to_string(width) +
                     "x" + std::to_string(height));
  }
  std::vector<float> rgb(3 * static_cast<size_t>(w) * h);
  for (int y = h - 1; y >= 0; --y) {
    in.read(reinterpret_cast<char*>(&rgb[3 * static_cast<size_t>(y) * w]),
            static_cast<std::streamsize>(3 * sizeof(float) * w));
  }
  if (!in) {
    throw InputError("'" + path + "': truncated (expected " + std::to_string(width) + "x" +
                     std::to_string(height) + " RGB floats)");
  }
  return rgb;
}

int Run(int argc, char** argv) {
  std::string scenario_path =
      std::string(PROBELESS_SOURCE_DIR) + "/data/scenarios/room_dynamic.yaml";
  int frames = 30;
  int threads = 2;
  int pt_spp = 64;
  bool pathtrace = true;
  bool pt_only = false;
  int pt_width = 0, pt_height = 0;  // 0: the room camera's 640x480
  int pt_rr = -1;                   // -1: the PathTraceOptions default
  uint64_t pt_seed = 1;
  std::string json;
  std::string pt_image, pt_raw, pt_ref;
  probeless::node::FlagParser flags(
      "raytrace_bench",
      "speed of the ray tracer and the simulator: simulator frames, the renderer alone, batched\n"
      "closest-hit and occlusion queries, one path-traced frame of the furnished room");
  flags.Add("--scenario", &scenario_path, "FILE.yaml", "the scenario of rows 1-4");
  flags.Add("--frames", &frames, "N", "simulator frames", 1);
  flags.Add("--threads", &threads, "N", "render threads", 1);
  flags.Add("--json", &json, "OUT", "write the figures as JSON");
  flags.Add("--pt-spp", &pt_spp, "N", "paths per pixel of the path trace", 1);
  flags.Add("--pt-image", &pt_image, "OUT.ppm", "write the path-traced image");
  flags.AddSwitch(
      "--no-pt", [&] { pathtrace = false; }, "skip the path trace");
  flags.Add("--pt-only", &pt_only, "only the path trace (skip rows 1-4)");
  flags.AddCallback("--pt-size", "WxH", "path-trace size (default: the room camera's 640x480)",
                    [&](const std::string& v) {
                      const size_t x = v.find('x');
                      if (x == std::string::npos)
                        throw probeless::node::UsageError("--pt-size expects WxH, got " + v);
                      pt_width = parse::ParseInteger<int>("--pt-size", v.substr(0, x), 1);
                      pt_height = parse::ParseInteger<int>("--pt-size", v.substr(x + 1), 1);
                    });
  flags.Add("--pt-seed", &pt_seed, "S", "path-trace seed", 0);
  flags.Add("--pt-rr", &pt_rr, "N",
            "Russian roulette after N bounces (-1: PathTraceOptions default)", 0);
  flags.Add("--pt-raw", &pt_raw, "OUT.pfm", "write the path trace's linear RGB");
  flags.Add("--pt-ref", &pt_ref, "REF.pfm", "rms error of the path trace against this reference");
  if (!flags.Parse(argc, argv)) return 0;
  if (frames < 1 || threads < 1 || pt_spp < 1) {
    throw probeless::node::UsageError("--frames, --threads and --pt-spp must be >= 1");
  }
  if (pt_only && !pathtrace)
    throw probeless::node::UsageError("--pt-only and --no-pt exclude each other");
  sim::Scenario scenario = sim::LoadScenario(scenario_path);
  const uint64_t n = std::min<uint64_t>(frames, scenario.frames);
  sim::Simulator simulator(scenario, threads);
  std::vector<Row> rows;

  // (1) Whole simulator frames, spread over the scenario.
  if (!pt_only) simulator.Render(0);  // warm-up: first BVH build, LUTs
  if (!pt_only) {
    Row r{"simulator frame (render + sensor + ground truth)"};
    const auto t0 = Clock::now();
    for (uint64_t k = 0; k < n; ++k) {
      const sim::SimFrame f =
          simulator.Render(k * (scenario.frames - 1) / std::max<uint64_t>(1, n - 1));
      r.rays += static_cast<double>(f.render.rays);
    }
    r.seconds = Seconds(t0, Clock::now());
    r.frames = static_cast<double>(n);
    rows.push_back(r);
  }
  // (2) The renderer alone on the last frame's scene state.
  const sim::SimFrame last = pt_only ? sim::SimFrame{} : simulator.Render(scenario.frames / 2);
  raytrace::RenderOptions options;
  options.shadows = scenario.render.shadows;
  raytrace::ThreadPool pool(threads);
  if (!pt_only) {
    Row r{"render only (primary + shadow rays, shading)"};
    const auto t0 = Clock::now();
    for (uint64_t k = 0; k < n; ++k) {
      r.rays += static_cast<double>(
          raytrace::Render(simulator.scene(), last.camera, options, &pool).rays);
    }
    r.seconds = Seconds(t0, Clock::now());
    r.frames = static_cast<double>(n);
    rows.push_back(r);
  }
  // (3), (4) Random rays from the camera position (incoherent), batched.
  std::vector<raytrace::Ray> rays(1 << 20);
  uint64_t state = 12345;
  auto uniform = [&] {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<float>(state >> 40) / 16777216.0f * 2 - 1;
  };
  const auto& t = last.camera.camera_to_world.translation;
  for (auto& ray : rays) {
    ray.origin = {static_cast<float>(t[0]), static_cast<float>(t[1]), static_cast<float>(t[2])};
    ray.direction = raytrace::Normalize({uniform(), uniform(), uniform()});
    ray.t_far = 100;
  }
  if (!pt_only) {
    Row r{"closest hit, 1M random rays (Scene::Intersect)"};
    std::vector<raytrace::Hit> hits(rays.size());
    const auto t0 = Clock::now();
    simulator.scene().Intersect(rays, hits, &pool);
    r.seconds = Seconds(t0, Clock::now());
    r.rays = static_cast<double>(rays.size());
    rows.push_back(r);
  }
  if (!pt_only) {
    Row r{"occlusion, 1M random rays (Scene::Occluded)"};
    std::vector<uint8_t> visible(rays.size());
    const auto t0 = Clock::now();
    simulator.scene().Occluded(rays, visible, &pool);
    r.seconds = Seconds(t0, Clock::now());
    r.rays = static_cast<double>(rays.size());
    rows.push_back(r);
  }

  // (5) One path-traced frame of the furnished room.
  raytrace::Scene room;
  raytrace::Camera room_camera = raytrace_bench::BuildPathTraceRoom(room);
  if (pt_width > 0) {  // the same view, smaller: the focal length and centre scale with the width
    const double s = static_cast<double>(pt_width) / room_camera.width;
    room_camera.fx *= s;
    room_camera.fy *= s;
    room_camera.cx = (room_camera.cx + 0.5) * s - 0.5;
    room_camera.cy = (room_camera.cy + 0.5) * s - 0.5;
    room_camera.width = pt_width;
    room_camera.height = pt_height;
  }
  raytrace::PathTraceOptions pt;
  pt.samples_per_pixel = pt_spp;
  pt.max_bounces = 3;
  pt.seed = pt_seed;
  if (pt_rr >= 0) pt.russian_roulette_after = pt_rr;
  double pt_rms = -1;
  if (pathtrace) {
    raytrace::Camera tiny = room_camera;  // warm-up: the GGX albedo tables are built on first use
    tiny.width = tiny.height = 1;
    raytrace::PathTrace(room, tiny, pt, &pool);
    Row r{"path trace " + std::to_string(room_camera.width) + "x" +
          std::to_string(room_camera.height) + ", " + std::to_string(pt_spp) +
          " spp, 3 bounces (room)"};
    const double cpu0 = CpuSeconds();
    const auto t0 = Clock::now();
    const raytrace::Frame f = raytrace::PathTrace(room, room_camera, pt, &pool);
    r.seconds = Seconds(t0, Clock::now());
    r.cpu_seconds = CpuSeconds() - cpu0;
    r.frames = 1;
    r.rays = static_cast<double>(f.rays);
    rows.push_back(r);
    if (!pt_image.empty()) WritePpm(pt_image, f);
    if (!pt_raw.empty()) WritePfm(pt_raw, f);
    if (!pt_ref.empty()) {
      const std::vector<float> ref = ReadPfm(pt_ref, f.width, f.height);
      double sum2 = 0, mean = 0;
      for (size_t i = 0; i < ref.size(); ++i) {
        const double d = static_cast<double>(f.linear_rgb[i]) - ref[i];
        sum2 += d * d;
        mean += ref[i];
      }
      mean /= static_cast<double>(ref.size());
      pt_rms = std::sqrt(sum2 / static_cast<double>(ref.size())) / mean;
    }
  }

  std::printf("raytrace_bench: %s, %dx%d, shadows %s, %zu triangles, %d threads (%u cores)\n",
              scenario.name.c_str(), scenario.camera.width, scenario.camera.height,
              options.shadows ? "on" : "off", simulator.scene().triangle_count(), threads,
              std::thread::hardware_concurrency());
  if (pathtrace) {
    std::printf("path-trace room: %zu triangles, %d objects, 1 sun disc + sky + 2 area lights\n",
                room.triangle_count(), room.object_count());
  }
  const double load = LoadAverage();
  std::printf("1-min load average at the end: %.2f\n", load);
  if (pt_rms >= 0) {
    std::printf("path trace rms error / reference mean: %.4f (seed %llu, %d spp, %dx%d)\n", pt_rms,
                static_cast<unsigned long long>(pt_seed), pt_spp, room_camera.width,
                room_camera.height);
  }
  std::printf("%-50s %10s %10s %14s %10s\n", "row", "fps", "ms/frame", "Mrays/s", "cpu s");
  for (const Row& r : rows) {
    const double fps = r.frames > 0 ? r.frames / r.seconds : 0;
    std::printf("%-50s %10.2f %10.1f %14.2f", r.name.c_str(), fps,
                r.frames > 0 ? 1000 * r.seconds / r.frames : 0.0, r.rays / r.seconds / 1e6);
    if (r.cpu_seconds >= 0) std::printf(" %10.2f", r.cpu_seconds);
    std::printf("\n");
  }
  if (!json.empty()) {
    std::ofstream out(json);
    out << "{\n  \"scenario\": \"" << scenario.name << "\",\n  \"width\": " << scenario.camera.width
        << ",\n  \"height\": " << scenario.camera.height
        << ",\n  \"shadows\": " << (options.shadows ? "true" : "false")
        << ",\n  \"triangles\": " << simulator.scene().triangle_count()
        << ",\n  \"threads\": " << threads << ",\n  \"frames\": " << n
        << ",\n  \"load_1min\": " << load << ",\n  \"rows\": [\n";
    for (size_t i = 0; i < rows.size(); ++i) {
      const Row& r = rows[i];
      out << "    {\"name\": \"" << r.name << "\", \"seconds\": " << r.seconds
          << ", \"fps\": " << (r.frames > 0 ? r.frames / r.seconds : 0)
          << ", \"rays\": " << static_cast<uint64_t>(r.rays)
          << ", \"rays_per_second\": " << static_cast<uint64_t>(r.rays / r.seconds);
      if (r.cpu_seconds >= 0) out << ", \"cpu_seconds\": " << r.cpu_seconds;
      out << "}" << (i + 1 < rows.size() ? "," : "") << "\n";
    }
    out << "  ]";
    if (pathtrace) {
      out << ",\n  \"pathtrace\": {\"scene\": \"pathtrace_room\", \"width\": " << room_camera.width
          << ", \"height\": " << room_camera.height << ", \"samples_per_pixel\": " << pt_spp
          << ", \"max_bounces\": " << pt.max_bounces
          << ", \"russian_roulette_after\": " << pt.russian_roulette_after
          << ", \"triangles\": " << room.triangle_count() << ", \"threads\": " << threads << "}";
    }
    out << "\n}\n";
    if (!out) throw std::runtime_error("cannot write '" + json + "'");
    std::printf("wrote %s\n", json.c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("raytrace_bench", [&] { return Run(argc, argv); });
}
