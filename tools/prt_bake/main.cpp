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
#include <optional>
#include <string>
#include <vector>

#include "probeless/node/flags.h"
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

// The options of the command line, nothing after --help (the usage is printed). Throws
// node::UsageError.
std::optional<Options> Parse(int argc, char** argv) {
  Options o;
  node::FlagParser flags(
      "prt_bake",
      "precomputed radiance transfer for a virtual object (Knorr & Kurz 2014 sec. 4.2, eq. 20):\n"
      "  prt_bake (MESH | --demo nose|cap|glasses) --out FILE.prt [options]\n"
      "  prt_bake --benchmark [--threads N] [--samples N]   (last line: \"X.X M rays/s\")");
  flags.AddPositional("MESH", &o.input, "MESH.obj or MESH.ply, in the bake frame");
  flags.Add("--demo", &o.demo, "nose|cap|glasses", "a built-in demo object instead of MESH");
  flags.Add("--out", &o.out, "FILE.prt", "the transfer file to write (required)");
  flags.Add("--occluder", &o.occluder, "head|none|SCENE",
            "the proxy head, nothing, or a scene mesh (.obj, .ply)");
  flags.Add("--bands", &o.bake.bands, "B", "SH bands (3 or 4)", 1);
  flags.Add("--samples", &o.bake.samples, "N", "rays per vertex (rounded down to a square)", 1);
  flags.Add("--seed", &o.bake.seed, "S", "sampling seed", 0);
  flags.Add("--bounce", &o.bake.interreflection, "one interreflection bounce");
  flags.AddSwitch(
      "--no-self-occlusion", [&] { o.bake.self_occlusion = false; },
      "the object does not shadow itself");
  flags.Add("--threads", &o.bake.threads, "N", "bake threads", 1);
  flags.AddCallback(
      "--scale", "F", "scale the mesh by F (> 0)",
      [&](const std::string& text) {
        o.scale = static_cast<float>(parse::ParsePositiveDouble("--scale", text));
      },
      "1");
  flags.Add("--quiet", &o.quiet, "no progress bar");
  flags.Add("--benchmark", &o.benchmark,
            "bake the built-in 50k-vertex scene with the proxy head and print the speed");
  if (!flags.Parse(argc, argv)) return std::nullopt;
  if (o.benchmark) return o;
  if (o.input.empty() == o.demo.empty()) {
    throw node::UsageError("give exactly one of MESH or --demo NAME");
  }
  if (o.out.empty()) throw node::UsageError("--out FILE.prt is required");
  if (!(o.scale > 0)) throw node::UsageError("--scale must be > 0");
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

// Not node::RunMain: every error is "prt_bake: <message>" and exit code 2 (docs/render.md).
int main(int argc, char** argv) {
  try {
    const std::optional<Options> parsed = Parse(argc, argv);
    if (!parsed) return 0;
    Options o = *parsed;
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
