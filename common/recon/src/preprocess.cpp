#include "probeless/recon/preprocess.h"

#include <algorithm>
#include <cmath>

namespace probeless::recon {

namespace {
constexpr int kRowTasks = 16;

// Runs fn(y0, y1) over `height` rows split into kRowTasks bands.
template <class Fn>
void ForRows(ThreadPool* pool, int height, Fn fn) {
  const int tasks = std::min(kRowTasks, std::max(1, height));
  ParallelFor(pool, tasks, [&](int task) {
    const int y0 = height * task / tasks;
    const int y1 = height * (task + 1) / tasks;
    fn(y0, y1);
  });
}
}  // namespace

void DepthFromUnits(const uint16_t* units, int width, int height, size_t stride_elements,
                    double metres_per_unit, float min_m, float max_m, DepthImage& out) {
  if (width <= 0 || height <= 0 || units == nullptr) {
    throw ReconError("depth: empty image (" + std::to_string(width) + "x" + std::to_string(height) +
                     ")");
  }
  if (stride_elements < static_cast<size_t>(width)) {
    throw ReconError("depth: row stride " + std::to_string(stride_elements) +
                     " is smaller than the width " + std::to_string(width));
  }
  if (!std::isfinite(metres_per_unit) || !(metres_per_unit > 0)) {
    throw ReconError("depth: metres per unit must be finite and > 0");
  }
  out.Resize(width, height);
  const float scale = static_cast<float>(metres_per_unit);
  for (int y = 0; y < height; ++y) {
    const uint16_t* row = units + y * stride_elements;
    float* dst = &out.At(0, y);
    for (int x = 0; x < width; ++x) {
      const float d = static_cast<float>(row[x]) * scale;
      dst[x] = (row[x] != 0 && row[x] != 65535 && d >= min_m && d <= max_m) ? d : 0.0f;
    }
  }
}

void BilateralFilter(const DepthImage& in, const PreprocessOptions& options, DepthImage& out,
                     ThreadPool* pool) {
  out.Resize(in.width, in.height);
  const int r = options.bilateral_radius;
  if (r <= 0) {
    out.data = in.data;
    return;
  }
  // Spatial weights precomputed; range weight exp(-dd^2 / (2 sigma_d^2)).
  std::vector<float> spatial((2 * r + 1) * (2 * r + 1));
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx)
      spatial[(dy + r) * (2 * r + 1) + dx + r] =
          std::exp(-(dx * dx + dy * dy) / (2 * options.sigma_space_px * options.sigma_space_px));
  const float inv_2sd2 = 1.0f / (2 * options.sigma_depth_m * options.sigma_depth_m);
  const float max_diff = 3 * options.sigma_depth_m;
  // Range weights tabulated over |diff| in [0, 3 sigma] (65 bins) instead of exp per sample.
  constexpr int kBins = 64;
  float range[kBins + 1];
  for (int i = 0; i <= kBins; ++i) {
    const float diff = max_diff * i / kBins;
    range[i] = std::exp(-diff * diff * inv_2sd2);
  }
  const float bins_per_m = kBins / max_diff;
  const int w = in.width, h = in.height;
  ForRows(pool, h, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y) {
      for (int x = 0; x < w; ++x) {
        const float c = in.At(x, y);
        if (c == 0) {
          out.At(x, y) = 0;
          continue;
        }
        float sum = 0, wsum = 0;
        const int ya = std::max(0, y - r), yb = std::min(h - 1, y + r);
        const int xa = std::max(0, x - r), xb = std::min(w - 1, x + r);
        for (int yy = ya; yy <= yb; ++yy) {
          const float* row = &in.At(0, yy);
          const float* sw = &spatial[(yy - y + r) * (2 * r + 1) + r - x];
          for (int xx = xa; xx <= xb; ++xx) {
            const float d = row[xx];
            const float diff = d - c;
            if (d == 0 || std::fabs(diff) > max_diff) continue;
            const float wgt = sw[xx] * range[static_cast<int>(std::fabs(diff) * bins_per_m + 0.5f)];
            sum += wgt * d;
            wsum += wgt;
          }
        }
        out.At(x, y) = sum / wsum;
      }
    }
  });
}

namespace {
// 2x2 block average of the pixels within 3 sigma of the block's first valid pixel.
void Downsample(const DepthImage& in, float max_diff, DepthImage& out) {
  out.Resize(in.width / 2, in.height / 2);
  for (int y = 0; y < out.height; ++y) {
    for (int x = 0; x < out.width; ++x) {
      const float v[4] = {in.At(2 * x, 2 * y), in.At(2 * x + 1, 2 * y), in.At(2 * x, 2 * y + 1),
                          in.At(2 * x + 1, 2 * y + 1)};
      float ref = 0;
      for (float d : v)
        if (d > 0) {
          ref = d;
          break;
        }
      float sum = 0;
      int n = 0;
      for (float d : v) {
        if (d > 0 && std::fabs(d - ref) <= max_diff) {
          sum += d;
          ++n;
        }
      }
      out.At(x, y) = n > 0 ? sum / n : 0.0f;
    }
  }
}
}  // namespace

void ComputeVertexMap(const DepthImage& depth, const Intrinsics& k, Vec3Image& out,
                      ThreadPool* pool) {
  out.Resize(depth.width, depth.height);
  const float ifx = 1.0f / k.fx, ify = 1.0f / k.fy;
  ForRows(pool, depth.height, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y) {
      const float ny = (y - k.cy) * ify;
      for (int x = 0; x < depth.width; ++x) {
        const float d = depth.At(x, y);
        out.At(x, y) = d > 0 ? Vec3f{(x - k.cx) * ifx * d, ny * d, d} : Vec3f{};
      }
    }
  });
}

void ComputeNormalMap(const Vec3Image& v, Vec3Image& out, ThreadPool* pool) {
  out.Resize(v.width, v.height);
  const int w = v.width, h = v.height;
  constexpr float kMaxJump = 0.1f;
  ForRows(pool, h, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y) {
      for (int x = 0; x < w; ++x) {
        Vec3f n{};
        if (x > 0 && x + 1 < w && y > 0 && y + 1 < h) {
          const Vec3f c = v.At(x, y), l = v.At(x - 1, y), r = v.At(x + 1, y), u = v.At(x, y - 1),
                      d = v.At(x, y + 1);
          if (c.z > 0 && l.z > 0 && r.z > 0 && u.z > 0 && d.z > 0 &&
              std::fabs(r.z - l.z) < kMaxJump * c.z && std::fabs(d.z - u.z) < kMaxJump * c.z) {
            // dy x dx points towards the camera for a frontal surface (x right, y down).
            n = Normalized(Cross(d - u, r - l));
            if (Dot(n, c) > 0) n = -1.0f * n;
          }
        }
        out.At(x, y) = n;
      }
    }
  });
}

void Preprocess(const DepthImage& depth_m, const Intrinsics& intrinsics,
                const PreprocessOptions& options, FramePyramid& out, ThreadPool* pool) {
  intrinsics.Validate("preprocess");
  if (depth_m.Empty()) throw ReconError("preprocess: empty depth image");
  if (depth_m.width != intrinsics.width || depth_m.height != intrinsics.height) {
    throw ReconError("preprocess: depth is " + std::to_string(depth_m.width) + "x" +
                     std::to_string(depth_m.height) + " but the intrinsics are for " +
                     std::to_string(intrinsics.width) + "x" + std::to_string(intrinsics.height));
  }
  if (options.levels < 1 || options.levels > 4) {
    throw ReconError("preprocess: levels must be 1..4, got " + std::to_string(options.levels));
  }
  if (options.first_level < 0 || options.first_level > 2) {
    throw ReconError("preprocess: first_level must be 0..2, got " +
                     std::to_string(options.first_level));
  }
  const int first = options.first_level;
  const int total = first + options.levels;
  out.raw_depth = depth_m;
  out.intrinsics.resize(total);
  out.depth.resize(total);
  out.vertices.resize(total);
  out.normals.resize(total);
  if (first == 0) {
    BilateralFilter(depth_m, options, out.depth[0], pool);
  } else {
    out.depth[0] = depth_m;
  }
  DepthImage unfiltered;
  for (int l = 0; l < total; ++l) {
    out.intrinsics[l] = intrinsics.Level(l);
    if (l > 0) {
      if (l == first) {
        Downsample(out.depth[l - 1], 3 * options.sigma_depth_m, unfiltered);
        BilateralFilter(unfiltered, options, out.depth[l], pool);
      } else {
        Downsample(out.depth[l - 1], 3 * options.sigma_depth_m, out.depth[l]);
      }
    }
    if (l < first) {
      out.vertices[l] = Vec3Image{};
      out.normals[l] = Vec3Image{};
      continue;
    }
    ComputeVertexMap(out.depth[l], out.intrinsics[l], out.vertices[l], pool);
    ComputeNormalMap(out.vertices[l], out.normals[l], pool);
  }
}

}  // namespace probeless::recon
