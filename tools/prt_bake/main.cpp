// prt_bake: precomputed radiance transfer for a virtual object (Knorr & Kurz 2014 §4.2, eq. 20).
//
//   prt_bake (MESH.obj|MESH.ply | --demo nose|cap|glasses) --out FILE.prt
//            [--occluder head|none|SCENE.obj|SCENE.ply] [--bands 3|4] [--samples N] [--seed S]
//            [--bounce] [--no-self-occlusion] [--threads N] [--scale F] [--quiet]
//   prt_bake --benchmark [--threads N] [--samples N]
//
// Meshes are taken in the bake frame: the face frame for face-anchored objects (the default
// occluder is the proxy head placed there), the world frame for scene meshes. The output format
// is documented in docs/render.md. --benchmark bakes the built-in 50k-vertex scene with the proxy
// head and prints, as its last line, "X.X M rays/s". Exit 0 on success, 2 on bad options or input.
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <exception>
#include <string>
#include <vector>

#include "probeless/parse/number.h"
#include "probeless/prt/demo_objects.h"
#include "probeless/prt/prt.h"

namespace {

using namespace probeless;

struct Options {
  std::string input;
  std::string demo;
  std::string out;
  std::string occluder = "head";
  prt::BakeOptions bake;
  float scale = 1;
  bool quiet = false;
  bool benchmark = false;
};

constexpr const char* kUsage =
    "usage: prt_bake (MESH | --demo nose|cap|glasses) --out FILE.prt [--occluder "
    "head|none|SCENE] [--bands B] [--samples N] [--seed S] [--bounce] "
    "[--no-self-occlusion] [--threads N] [--scale F] [--quiet]\n"
    "       prt_bake --benchmark [--threads N] [--samples N]\n";

[[noreturn]] void Usage(const std::string& message) {
  std::fprintf(stderr, "prt_bake: %s\n%s", message.c_str(), kUsage);
  std::exit(2);
}

// parse::'s rules; strtol took "3x" as 3 and a 20-digit count as LONG_MAX.
template <class T>
T ParseInt(const std::string& option, const std::string& text, T min) {
  try {
    return parse::ParseInteger<T>(option, text, min);
  } catch (const parse::NumberError& e) {
    Usage(e.what());
  }
}

Options Parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) Usage(a + " needs a value");
      return argv[++i];
    };
    if (a == "--out")
      o.out = value();
    else if (a == "--demo")
      o.demo = value();
    else if (a == "--occluder")
      o.occluder = value();
    else if (a == "--bands")
      o.bake.bands = ParseInt<int>(a, value(), 1);
    else if (a == "--samples")
      o.bake.samples = ParseInt<int>(a, value(), 1);
    else if (a == "--seed")
      o.bake.seed = ParseInt<uint64_t>(a, value(), 0);
    else if (a == "--threads")
      o.bake.threads = ParseInt<int>(a, value(), 1);
    else if (a == "--scale") {
      const std::string text = value();
      const auto scale = parse::TryParseDouble(text, 0);
      if (!scale || *scale <= 0) Usage("--scale expects a positive number, got '" + text + "'");
      o.scale = static_cast<float>(*scale);
    } else if (a == "--bounce")
      o.bake.interreflection = true;
    else if (a == "--no-self-occlusion")
      o.bake.self_occlusion = false;
    else if (a == "--quiet")
      o.quiet = true;
    else if (a == "--benchmark")
      o.benchmark = true;
    else if (a == "-h" || a == "--help") {
      std::printf("%s", kUsage);
      std::exit(0);
    } else if (!a.empty() && a[0] == '-')
      Usage("unknown option " + a);
    else if (o.input.empty())
      o.input = a;
    else
      Usage("more than one input mesh");
  }
  if (o.benchmark) return o;
  if (o.input.empty() == o.demo.empty()) Usage("give exactly one of MESH or --demo NAME");
  if (o.out.empty()) Usage("--out FILE.prt is required");
  if (!(o.scale > 0)) Usage("--scale must be > 0");
  return o;
}

// A text progress bar on stderr: "[#####.....]  50% (25000/50000 vertices)".
void Progress(size_t done, size_t total) {
  constexpr int kWidth = 40;
  const int filled = total ? static_cast<int>(kWidth * done / total) : kWidth;
  std::string bar(filled, '#');
  bar.resize(kWidth, '.');
  std::fprintf(stderr, "\r[%s] %3d%% (%zu/%zu)", bar.c_str(),
               total ? static_cast<int>(100 * done / total) : 100, done, total);
  if (done >= total) std::fprintf(stderr, "\n");
  std::fflush(stderr);
}

}  // namespace

int main(int argc, char** argv) {
  Options o = Parse(argc, argv);
  try {
    if (!o.quiet) o.bake.progress = Progress;
    std::vector<prt::Occluder> occluders;
    raytrace::Mesh mesh;
    if (o.benchmark) {
      mesh = prt::MakeBenchmarkObject(50000);
      occluders.push_back({prt::ProxyHead(), {}});
    } else {
      if (!o.demo.empty()) {
        mesh = prt::MakeDemoObject(o.demo);
      } else {
        mesh = raytrace::LoadMesh(o.input);
      }
      if (o.scale != 1) mesh.Scale(o.scale);
      if (o.occluder == "head") {
        occluders.push_back({prt::ProxyHead(), {}});
      } else if (o.occluder != "none") {
        occluders.push_back({raytrace::LoadMesh(o.occluder), {}});
      }
    }
    prt::BakeStats stats;
    const std::clock_t cpu_start = std::clock();
    const prt::TransferMesh baked = prt::Bake(mesh, occluders, o.bake, &stats);
    const double rays = static_cast<double>(stats.shadow_rays + stats.bounce_rays);
    // Throughput of the ray passes (the one-off BVH build is reported separately in the JSON).
    const double mrays = rays / stats.trace_seconds / 1e6;
    const double cpu_seconds = static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC;
    if (o.benchmark) {
      std::printf(
          "{\"vertices\": %zu, \"samples_per_vertex\": %llu, \"threads\": %d, "
          "\"rays\": %.0f, \"seconds\": %.3f, \"trace_seconds\": %.3f, \"cpu_seconds\": %.3f, "
          "\"mrays_per_cpu_second\": %.2f}\n",
          baked.mesh.positions.size(),
          static_cast<unsigned long long>(stats.shadow_rays / baked.mesh.positions.size()),
          o.bake.threads, rays, stats.seconds, stats.trace_seconds, cpu_seconds,
          rays / cpu_seconds / 1e6);
      std::printf("%.1f M rays/s\n", mrays);
      return 0;
    }
    prt::SavePrt(baked, o.out);
    std::fprintf(
        stderr, "prt_bake: %zu vertices, %d bands, %.0f rays in %.2f s (%.1f M rays/s) -> %s\n",
        baked.mesh.positions.size(), baked.bands, rays, stats.seconds, mrays, o.out.c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "prt_bake: %s\n", e.what());
    return 2;
  }
}
