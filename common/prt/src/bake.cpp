#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <numbers>
#include <string>

#include "probeless/prt/prt.h"
#include "probeless/raytrace/scene.h"
#include "sh_fast.h"

namespace probeless::prt {

namespace {

using raytrace::Vec3;

// SplitMix64: the fixed-seed generator of the stratified jitter (one stream per vertex).
struct SplitMix64 {
  uint64_t state;
  uint64_t Next() {
    uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1) from the top 24 bits.
  float Uniform() { return static_cast<float>(Next() >> 40) * (1.0f / 16777216.0f); }
};

// An orthonormal basis (t, b, n) around unit n (Duff et al. 2017).
void Basis(const Vec3& n, Vec3& t, Vec3& b) {
  const float sign = std::copysign(1.0f, n.z);
  const float a = -1.0f / (sign + n.z);
  const float bb = n.x * n.y * a;
  t = {1.0f + sign * n.x * n.x * a, sign * bb, -sign * n.x};
  b = {bb, sign + n.y * n.y * a, -n.y};
}

// Vertices per work item of the thread pool.
constexpr size_t kBlock = 32;

}  // namespace

void TransferMesh::Validate(const std::string& what) const {
  if (bands < 1 || bands > 5) {
    throw PrtError(what + ": bands " + std::to_string(bands) + " out of range 1..5");
  }
  try {
    mesh.Validate(what);
  } catch (const raytrace::RaytraceError& e) {
    throw PrtError(e.what());
  }
  if (mesh.normals.size() != mesh.positions.size()) {
    throw PrtError(what + ": mesh has no vertex normals");
  }
  if (transfer.size() != mesh.positions.size() * static_cast<size_t>(coefficient_count())) {
    throw PrtError(what + ": " + std::to_string(transfer.size()) + " transfer values for " +
                   std::to_string(mesh.positions.size()) + " vertices x " +
                   std::to_string(coefficient_count()) + " coefficients");
  }
}

std::vector<float> UnshadowedTransfer(const Vec3& n, int bands) {
  if (bands < 1 || bands > 5) {
    throw PrtError("UnshadowedTransfer: bands " + std::to_string(bands) + " out of range 1..5");
  }
  std::vector<float> t(static_cast<size_t>(bands * bands));
  sh::EvaluateBasis<float>(bands, n.x, n.y, n.z, t.data());
  for (int k = 0; k < bands * bands; ++k) {
    t[k] *= static_cast<float>(sh::ClampedCosineCoefficient(sh::DegreeOf(k)) / std::numbers::pi);
  }
  return t;
}

TransferMesh Bake(const raytrace::Mesh& input, std::span<const Occluder> occluders,
                  const BakeOptions& options, BakeStats* stats) {
  const auto start = std::chrono::steady_clock::now();
  if (options.bands < 1 || options.bands > 5) {
    throw PrtError("prt::Bake: bands " + std::to_string(options.bands) + " out of range 1..5");
  }
  const int strata = static_cast<int>(std::floor(std::sqrt(static_cast<double>(options.samples))));
  if (strata < 1) {
    throw PrtError("prt::Bake: samples must be >= 1, got " + std::to_string(options.samples));
  }
  if (options.threads < 1) {
    throw PrtError("prt::Bake: threads must be >= 1, got " + std::to_string(options.threads));
  }
  if (input.positions.empty() || input.triangles.empty()) {
    throw PrtError("prt::Bake: the mesh has no triangles");
  }
  TransferMesh out;
  out.mesh = input;
  try {
    out.mesh.Validate("prt::Bake mesh");
  } catch (const raytrace::RaytraceError& e) {
    throw PrtError(e.what());
  }
  if (out.mesh.normals.size() != out.mesh.positions.size()) out.mesh.ComputeNormals();
  out.bands = options.bands;
  const int count = options.bands * options.bands;
  const size_t vertices = out.mesh.positions.size();
  const int samples = strata * strata;
  out.transfer.assign(vertices * count, 0.0f);

  raytrace::Scene scene;
  int object_index = -1;
  if (options.self_occlusion || options.interreflection) {
    object_index = scene.AddObject(out.mesh, raytrace::Material{}, raytrace::Transform{}, 1);
  }
  for (const Occluder& occluder : occluders) {
    try {
      scene.AddObject(occluder.mesh, raytrace::Material{}, occluder.placement, 2);
    } catch (const raytrace::RaytraceError& e) {
      throw PrtError(std::string("prt::Bake occluder: ") + e.what());
    }
  }
  const bool any_geometry = scene.object_count() > 0;
  if (any_geometry) scene.Commit();

  raytrace::ThreadPool pool(options.threads);
  const size_t blocks = (vertices + kBlock - 1) / kBlock;
  const float inv_samples = 1.0f / static_cast<float>(samples);

  // Generates the cosine-weighted stratified directions of vertex v into dirs (samples entries).
  auto directions = [&](size_t v, std::vector<Vec3>& dirs) {
    SplitMix64 rng{options.seed * 0x2545F4914F6CDD1Dull ^ (static_cast<uint64_t>(v) + 1)};
    Vec3 n = raytrace::Normalize(out.mesh.normals[v]);
    if (raytrace::Length(n) == 0) n = {0, 0, -1};
    Vec3 t, b;
    Basis(n, t, b);
    dirs.resize(samples);
    for (int i = 0; i < strata; ++i) {
      for (int j = 0; j < strata; ++j) {
        const float u1 = (static_cast<float>(i) + rng.Uniform()) / static_cast<float>(strata);
        const float u2 = (static_cast<float>(j) + rng.Uniform()) / static_cast<float>(strata);
        const float r = std::sqrt(u1);
        const float phi = 2.0f * std::numbers::pi_v<float> * u2;
        const float lx = r * std::cos(phi), ly = r * std::sin(phi);
        const float lz = std::sqrt(std::max(0.0f, 1.0f - u1));
        dirs[i * strata + j] = t * lx + b * ly + n * lz;
      }
    }
    return n;
  };

  std::atomic<size_t> done{0};
  auto direct_block = [&](size_t block) {
    const size_t begin = block * kBlock;
    const size_t end = std::min(vertices, begin + kBlock);
    const size_t n = end - begin;
    // Sample-major order: ray (s, v) at s * n + (v - begin), so consecutive rays start at
    // neighbouring vertices in nearly the same direction (coherent streams for Embree).
    std::vector<raytrace::Ray> rays(n * samples);
    std::vector<uint8_t> visible(rays.size(), 1);
    std::vector<std::vector<Vec3>> all_dirs(n);
    for (size_t v = begin; v < end; ++v) {
      const Vec3 normal = directions(v, all_dirs[v - begin]);
      const Vec3 origin = out.mesh.positions[v] + normal * options.ray_epsilon;
      for (int s = 0; s < samples; ++s) {
        rays[s * n + (v - begin)] = {origin, all_dirs[v - begin][s], 0.0f, 1e30f};
      }
    }
    if (any_geometry) scene.Occluded(rays, visible, nullptr);
    float y[25];
    for (size_t v = begin; v < end; ++v) {
      float* t = out.transfer.data() + v * count;
      for (int s = 0; s < samples; ++s) {
        if (!visible[s * n + (v - begin)]) continue;
        const Vec3& d = all_dirs[v - begin][s];
        internal::FastBasis(options.bands, d.x, d.y, d.z, y);
        for (int k = 0; k < count; ++k) t[k] += y[k];
      }
      for (int k = 0; k < count; ++k) t[k] *= inv_samples;
    }
    done.fetch_add(n);
  };

  // Runs fn over all blocks in chunks so progress is reported from the calling thread.
  auto run = [&](const std::function<void(size_t)>& fn, size_t offset, size_t total) {
    const size_t chunk = std::max<size_t>(64, blocks / 50);
    for (size_t first = 0; first < blocks; first += chunk) {
      const size_t n = std::min(chunk, blocks - first);
      pool.ParallelFor(n, [&](size_t i) { fn(first + i); });
      if (options.progress)
        options.progress(offset + std::min(vertices, (first + n) * kBlock), total);
    }
  };
  const size_t total = options.interreflection ? 2 * vertices : vertices;
  const auto trace_start = std::chrono::steady_clock::now();
  run(direct_block, 0, total);
  uint64_t bounce_rays = 0;

  if (options.interreflection) {
    // Sloan 2002: T1 = T0 + (1/N) sum over samples hitting the object of albedo(hit) T0(hit); with
    // cosine-weighted sampling the cos/pi weight cancels against the pdf.
    std::vector<float> bounced(out.transfer.size(), 0.0f);
    const bool has_colors = out.mesh.colors.size() == vertices;
    auto bounce_block = [&](size_t block) {
      const size_t begin = block * kBlock;
      const size_t end = std::min(vertices, begin + kBlock);
      std::vector<Vec3> dirs;
      std::vector<raytrace::Ray> rays(samples);
      std::vector<raytrace::Hit> hits(samples);
      for (size_t v = begin; v < end; ++v) {
        const Vec3 n = directions(v, dirs);
        const Vec3 origin = out.mesh.positions[v] + n * options.ray_epsilon;
        for (int s = 0; s < samples; ++s) rays[s] = {origin, dirs[s], 0.0f, 1e30f};
        scene.Intersect(rays, hits, nullptr);
        float* acc = bounced.data() + v * count;
        for (int s = 0; s < samples; ++s) {
          const raytrace::Hit& h = hits[s];
          if (h.object != object_index) continue;
          const auto& tri = out.mesh.triangles[h.triangle];
          const float w[3] = {1 - h.u - h.v, h.u, h.v};
          // Only front faces (seen from outside) reflect light back.
          const Vec3 hn = out.mesh.normals[tri[0]] * w[0] + out.mesh.normals[tri[1]] * w[1] +
                          out.mesh.normals[tri[2]] * w[2];
          if (raytrace::Dot(hn, dirs[s]) >= 0) continue;
          Vec3 albedo = options.albedo;
          if (has_colors) {
            albedo = out.mesh.colors[tri[0]] * w[0] + out.mesh.colors[tri[1]] * w[1] +
                     out.mesh.colors[tri[2]] * w[2];
          }
          const float grey = (albedo.x + albedo.y + albedo.z) / 3.0f;
          for (int c = 0; c < 3; ++c) {
            const float* t0 = out.transfer.data() + tri[c] * count;
            for (int k = 0; k < count; ++k) acc[k] += grey * w[c] * t0[k];
          }
        }
        for (int k = 0; k < count; ++k) acc[k] *= inv_samples;
      }
    };
    run(bounce_block, vertices, total);
    for (size_t i = 0; i < bounced.size(); ++i) out.transfer[i] += bounced[i];
    bounce_rays = static_cast<uint64_t>(vertices) * samples;
  }

  if (stats != nullptr) {
    stats->shadow_rays = static_cast<uint64_t>(vertices) * samples;
    stats->bounce_rays = bounce_rays;
    const auto now = std::chrono::steady_clock::now();
    stats->seconds = std::chrono::duration<double>(now - start).count();
    stats->trace_seconds = std::chrono::duration<double>(now - trace_start).count();
  }
  return out;
}

}  // namespace probeless::prt
