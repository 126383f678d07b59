#include "probeless/recon/tsdf_volume.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>

#include "byte_io.h"

namespace probeless::recon {

namespace {
constexpr int kBrick = 8;
constexpr int kCoarse = 4;  // bricks per side of a coarse cell of the raycast's skip grid
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
// TSDF value of an unobserved voxel (weight 0): outside [-1, 1], so readers that only need to
// know "observed or not" test the value and skip the weight array (one memory access less per
// raycast sample). The first update overwrites it (running average with weight 0).
constexpr float kUnobserved = 2.0f;
constexpr float kUnobservedTest = 1.5f;  // tsdf > this <=> unobserved

// World -> camera (float, row-major) for the integration kernel.
struct RigidF {
  float r[9];
  float t[3];
  explicit RigidF(const Pose& p) {
    for (int i = 0; i < 9; ++i) r[i] = static_cast<float>(p.r[i]);
    for (int i = 0; i < 3; ++i) t[i] = static_cast<float>(p.t[i]);
  }
  Vec3f Apply(Vec3f v) const {
    return {r[0] * v.x + r[1] * v.y + r[2] * v.z + t[0],
            r[3] * v.x + r[4] * v.y + r[5] * v.z + t[1],
            r[6] * v.x + r[7] * v.y + r[8] * v.z + t[2]};
  }
  Vec3f Rotate(Vec3f v) const {
    return {r[0] * v.x + r[1] * v.y + r[2] * v.z, r[3] * v.x + r[4] * v.y + r[5] * v.z,
            r[6] * v.x + r[7] * v.y + r[8] * v.z};
  }
};

void ValidateDepth(const DepthImage& depth, const Intrinsics& k, const char* what) {
  k.Validate(what);
  if (depth.Empty()) throw ReconError(std::string(what) + ": empty depth image");
  if (depth.width != k.width || depth.height != k.height) {
    throw ReconError(std::string(what) + ": depth is " + std::to_string(depth.width) + "x" +
                     std::to_string(depth.height) + " but the intrinsics are for " +
                     std::to_string(k.width) + "x" + std::to_string(k.height));
  }
}
}  // namespace

void VolumeOptions::Validate() const {
  if (resolution < 8 || resolution > 1024 || resolution % kBrick != 0) {
    throw ReconError("volume: resolution must be a multiple of 8 in [8, 1024], got " +
                     std::to_string(resolution));
  }
  if (!std::isfinite(size_m) || !(size_m > 0)) throw ReconError("volume: size_m must be > 0");
  if (!std::isfinite(origin.x) || !std::isfinite(origin.y) || !std::isfinite(origin.z)) {
    throw ReconError("volume: origin must be finite");
  }
  if (!std::isfinite(truncation_m) || !(truncation_m > size_m / resolution)) {
    throw ReconError("volume: truncation_m must exceed one voxel (" +
                     std::to_string(size_m / resolution) + " m)");
  }
  if (max_weight < 1 || max_weight > 255) {
    throw ReconError("volume: max_weight must be in [1, 255], got " + std::to_string(max_weight));
  }
  if (mark_stride < 1 || carve_stride < 0) {
    throw ReconError("volume: mark_stride must be >= 1 and carve_stride >= 0");
  }
}

TsdfVolume::TsdfVolume(const VolumeOptions& options) : options_(options) {
  options_.Validate();
  res_ = options_.resolution;
  bricks_ = res_ / kBrick;
  voxel_size_ = options_.size_m / res_;
  inv_voxel_ = 1.0f / voxel_size_;
  const size_t n = static_cast<size_t>(res_) * res_ * res_;
  tsdf_.assign(n, kUnobserved);
  weight_.assign(n, 0);
  observed_.assign(static_cast<size_t>(bricks_) * bricks_ * bricks_, 0);
  surface_.assign(observed_.size(), 0);
  touched_.assign(observed_.size(), 0);
  coarse_side_ = (bricks_ + kCoarse - 1) / kCoarse;
  coarse_.assign(static_cast<size_t>(coarse_side_) * coarse_side_ * coarse_side_, 0);
}

void TsdfVolume::UpdateCoarse() {
  std::fill(coarse_.begin(), coarse_.end(), 0);
  for (size_t b = 0; b < surface_.size(); ++b) {
    if (!surface_[b]) continue;
    const int bi = static_cast<int>(b % bricks_), bj = static_cast<int>((b / bricks_) % bricks_),
              bk = static_cast<int>(b / (static_cast<size_t>(bricks_) * bricks_));
    coarse_[(static_cast<size_t>(bk / kCoarse) * coarse_side_ + bj / kCoarse) * coarse_side_ +
            bi / kCoarse] = 1;
  }
}

void TsdfVolume::Reset() {
  for (size_t b = 0; b < observed_.size(); ++b) {
    if (!observed_[b]) continue;
    std::fill_n(tsdf_.begin() + (b << 9), 512, kUnobserved);
    std::fill_n(weight_.begin() + (b << 9), 512, 0);
    observed_[b] = 0;
    surface_[b] = 0;
  }
  std::fill(coarse_.begin(), coarse_.end(), 0);
}

bool TsdfVolume::BrickObserved(int i, int j, int k) const {
  if (i < 0 || j < 0 || k < 0 || i >= res_ || j >= res_ || k >= res_) return false;
  return observed_[((k >> 3) * bricks_ + (j >> 3)) * bricks_ + (i >> 3)] != 0;
}

int TsdfVolume::ObservedBricks() const {
  return static_cast<int>(std::count(observed_.begin(), observed_.end(), uint8_t{1}));
}

void TsdfVolume::AppendObservedBricks(std::vector<std::byte>& out) const {
  detail::ByteWriter w(out);
  const uint32_t count = static_cast<uint32_t>(ObservedBricks());
  out.reserve(out.size() + 4 + static_cast<size_t>(count) * (4 + 512 * 5));
  w.Put(count);
  for (size_t b = 0; b < observed_.size(); ++b) {
    if (!observed_[b]) continue;
    w.Put(static_cast<uint32_t>(b));
    w.PutBytes(&tsdf_[b << 9], 512 * sizeof(float));
    w.PutBytes(&weight_[b << 9], 512);
  }
}

void TsdfVolume::ReadObservedBricks(std::span<const std::byte> in, size_t* offset,
                                    const std::string& name) {
  Reset();
  detail::ByteReader r(in.subspan(std::min(*offset, in.size())), name);
  try {
    const uint32_t count = r.Get<uint32_t>();
    if (count > observed_.size()) {
      throw ReconError(name + ": " + std::to_string(count) + " bricks, the volume has " +
                       std::to_string(observed_.size()));
    }
    r.Need(static_cast<size_t>(count) * (4 + 512 * 5));
    int64_t previous = -1;
    for (uint32_t n = 0; n < count; ++n) {
      const uint32_t b = r.Get<uint32_t>();
      if (b >= observed_.size() || static_cast<int64_t>(b) <= previous) {
        throw ReconError(name + ": brick index " + std::to_string(b) +
                         " out of range or not increasing (bricks 0.." +
                         std::to_string(observed_.size() - 1) + ")");
      }
      previous = b;
      float* tsdf = &tsdf_[static_cast<size_t>(b) << 9];
      uint8_t* weight = &weight_[static_cast<size_t>(b) << 9];
      r.GetBytes(tsdf, 512 * sizeof(float));
      r.GetBytes(weight, 512);
      observed_[b] = 1;
      float lowest = 1.0f;
      for (int v = 0; v < 512; ++v) {
        const bool ok = weight[v] == 0 ? tsdf[v] == kUnobserved
                                       : weight[v] <= options_.max_weight && tsdf[v] >= -1.0f &&
                                             tsdf[v] <= 1.0f;
        if (!ok) {
          throw ReconError(name + ": brick " + std::to_string(b) + " voxel " + std::to_string(v) +
                           " has weight " + std::to_string(weight[v]) + " and tsdf " +
                           std::to_string(tsdf[v]) + " (expected weight <= max_weight " +
                           std::to_string(options_.max_weight) +
                           " and tsdf in [-1, 1], or weight 0 unobserved)");
        }
        lowest = std::min(lowest, weight[v] ? tsdf[v] : 1.0f);
      }
      surface_[b] = lowest < 0.999f;
    }
  } catch (const ReconError&) {
    Reset();
    throw;
  }
  UpdateCoarse();
  *offset += r.offset();
}

IntegrateStats TsdfVolume::Integrate(const DepthImage& depth, const Intrinsics& k,
                                     const Pose& camera_to_world, ThreadPool* pool) {
  ValidateDepth(depth, k, "integrate");
  const RigidF c2w(camera_to_world);
  const RigidF w2c(camera_to_world.Inverse());
  const float mu = options_.truncation_m;
  const float brick_m = voxel_size_ * kBrick;
  const Vec3f o = options_.origin;
  const float inv_brick = 1.0f / brick_m;
  std::fill(touched_.begin(), touched_.end(), 0);

  // 1. Bricks touched by the truncation band [d - mu, d + mu] of the (subsampled) pixels, and
  //    already-observed bricks on the free-space part of sparser rays (carving).
  auto mark = [&](Vec3f p_world, bool only_observed) {
    const float bx = (p_world.x - o.x) * inv_brick, by = (p_world.y - o.y) * inv_brick,
                bz = (p_world.z - o.z) * inv_brick;
    if (bx < 0 || by < 0 || bz < 0 || bx >= bricks_ || by >= bricks_ || bz >= bricks_) return;
    const size_t b = (static_cast<size_t>(bz) * bricks_ + static_cast<size_t>(by)) * bricks_ +
                     static_cast<size_t>(bx);
    if (only_observed && !observed_[b]) return;
    std::atomic_ref<uint8_t>(touched_[b]).store(1, std::memory_order_relaxed);
  };
  const int stride = options_.mark_stride;
  const int carve = options_.carve_stride;
  const int rows = (k.height + stride - 1) / stride;
  const Vec3f cam = camera_to_world.Translation();
  ParallelFor(pool, 8, [&](int task) {
    for (int ry = rows * task / 8; ry < rows * (task + 1) / 8; ++ry) {
      const int y = ry * stride;
      for (int x = 0; x < k.width; x += stride) {
        const float d = depth.At(x, y);
        if (d <= 0) continue;
        const Vec3f ray{(x - k.cx) / k.fx, (y - k.cy) / k.fy, 1.0f};
        const Vec3f ray_w = c2w.Rotate(ray);
        for (int s = -2; s <= 2; ++s) mark(cam + (d + 0.5f * s * mu) * ray_w, false);
        if (carve > 0 && x % carve == 0 && y % carve == 0) {
          const float step = 0.5f * brick_m / Norm(ray);
          for (float z = 0.2f; z < d - mu; z += step) mark(cam + z * ray_w, true);
        }
      }
    }
  });
  std::vector<int> list;
  for (size_t b = 0; b < touched_.size(); ++b)
    if (touched_[b]) list.push_back(static_cast<int>(b));

  // 2. Projective update of every voxel of the touched bricks (KinectFusion eq. 9-11).
  const int tasks = std::min<int>(64, static_cast<int>(list.size()));
  std::vector<uint64_t> updated(std::max(tasks, 1), 0);
  const Vec3f ax = w2c.Rotate({voxel_size_, 0, 0});
  const Vec3f ay = w2c.Rotate({0, voxel_size_, 0});
  const Vec3f az = w2c.Rotate({0, 0, voxel_size_});
  const float inv_mu = 1.0f / mu;
  const int max_w = options_.max_weight;
  const int w = k.width, h = k.height;
  const float umax = w - 0.5f, vmax = h - 0.5f;
  ParallelFor(pool, tasks, [&](int task) {
    uint64_t count = 0;
    const size_t n = list.size();
    for (size_t li = n * task / tasks; li < n * (task + 1) / tasks; ++li) {
      const int b = list[li];
      const int bi = b % bricks_, bj = (b / bricks_) % bricks_, bk = b / (bricks_ * bricks_);
      float* tsdf = &tsdf_[static_cast<size_t>(b) << 9];
      uint8_t* weight = &weight_[static_cast<size_t>(b) << 9];
      const Vec3f corner{o.x + (bi * kBrick + 0.5f) * voxel_size_,
                         o.y + (bj * kBrick + 0.5f) * voxel_size_,
                         o.z + (bk * kBrick + 0.5f) * voxel_size_};
      const Vec3f base = w2c.Apply(corner);
      bool any = false;
      for (int vk = 0; vk < kBrick; ++vk) {
        for (int vj = 0; vj < kBrick; ++vj) {
          Vec3f p = base + static_cast<float>(vk) * az + static_cast<float>(vj) * ay;
          const int row = (vk << 6) | (vj << 3);
          for (int vi = 0; vi < kBrick; ++vi, p = p + ax) {
            if (p.z <= 0.05f) continue;
            const float iz = 1.0f / p.z;
            const float uf = k.fx * p.x * iz + k.cx;
            const float vf = k.fy * p.y * iz + k.cy;
            if (!(uf >= -0.5f && uf < umax && vf >= -0.5f && vf < vmax)) continue;
            const float d =
                depth.data[static_cast<size_t>(vf + 0.5f) * w + static_cast<size_t>(uf + 0.5f)];
            if (d <= 0) continue;
            const float sdf = d - p.z;
            if (sdf < -mu) continue;
            const float f = std::min(1.0f, sdf * inv_mu);
            const int idx = row | vi;
            const int wo = weight[idx];
            tsdf[idx] = (tsdf[idx] * wo + f) / (wo + 1);
            weight[idx] = static_cast<uint8_t>(std::min(wo + 1, max_w));
            any = true;
            ++count;
          }
        }
      }
      if (any) {
        observed_[b] = 1;
        float lowest = 1.0f;
        for (int v = 0; v < 512; ++v) lowest = std::min(lowest, weight[v] ? tsdf[v] : 1.0f);
        surface_[b] = lowest < 0.999f;
      }
    }
    updated[task] = count;
  });
  UpdateCoarse();
  IntegrateStats stats;
  stats.bricks = static_cast<int>(list.size());
  for (uint64_t c : updated) stats.voxels += c;
  (void)h;
  return stats;
}

namespace {
// Trilinear interpolation over the 8 voxels around continuous voxel coordinates g (voxel centres
// at integers); also the gradient (per voxel unit). False if any voxel is unobserved (tsdf =
// kUnobserved) or outside.
struct Sampler {
  const float* tsdf;
  int res;
  int bricks;
  size_t Index(int i, int j, int k) const {
    const int b = ((k >> 3) * bricks + (j >> 3)) * bricks + (i >> 3);
    return (static_cast<size_t>(b) << 9) | ((k & 7) << 6) | ((j & 7) << 3) | (i & 7);
  }
  bool Trilinear(float gx, float gy, float gz, float* value, Vec3f* grad) const {
    const int i = static_cast<int>(std::floor(gx)), j = static_cast<int>(std::floor(gy)),
              k = static_cast<int>(std::floor(gz));
    if (i < 0 || j < 0 || k < 0 || i + 1 >= res || j + 1 >= res || k + 1 >= res) return false;
    float c[8];
    if ((i & 7) != 7 && (j & 7) != 7 && (k & 7) != 7) {
      // All 8 voxels in one brick: fixed offsets from the first.
      const float* base = tsdf + Index(i, j, k);
      constexpr int kOffsets[8] = {0, 1, 8, 9, 64, 65, 72, 73};
      for (int n = 0; n < 8; ++n) c[n] = base[kOffsets[n]];
    } else {
      for (int n = 0; n < 8; ++n) c[n] = tsdf[Index(i + (n & 1), j + ((n >> 1) & 1), k + (n >> 2))];
    }
    for (int n = 0; n < 8; ++n)
      if (c[n] > kUnobservedTest) return false;
    const float fx = gx - i, fy = gy - j, fz = gz - k;
    const float c00 = c[0] + (c[1] - c[0]) * fx, c10 = c[2] + (c[3] - c[2]) * fx;
    const float c01 = c[4] + (c[5] - c[4]) * fx, c11 = c[6] + (c[7] - c[6]) * fx;
    const float c0 = c00 + (c10 - c00) * fy, c1 = c01 + (c11 - c01) * fy;
    *value = c0 + (c1 - c0) * fz;
    if (grad) {
      const float dx0 = (c[1] - c[0]) + ((c[3] - c[2]) - (c[1] - c[0])) * fy;
      const float dx1 = (c[5] - c[4]) + ((c[7] - c[6]) - (c[5] - c[4])) * fy;
      grad->x = dx0 + (dx1 - dx0) * fz;
      grad->y = (c10 - c00) + ((c11 - c01) - (c10 - c00)) * fz;
      grad->z = c1 - c0;
    }
    return true;
  }
};
}  // namespace

float TsdfVolume::TsdfAt(Vec3f p) const {
  const Sampler s{tsdf_.data(), res_, bricks_};
  float v;
  const Vec3f o = options_.origin;
  if (!s.Trilinear((p.x - o.x) * inv_voxel_ - 0.5f, (p.y - o.y) * inv_voxel_ - 0.5f,
                   (p.z - o.z) * inv_voxel_ - 0.5f, &v, nullptr)) {
    return kNaN;
  }
  return v;
}

bool TsdfVolume::NormalAt(Vec3f p, float step_voxels, Vec3f* normal) const {
  const Sampler s{tsdf_.data(), res_, bricks_};
  const Vec3f o = options_.origin;
  const float gx = (p.x - o.x) * inv_voxel_ - 0.5f, gy = (p.y - o.y) * inv_voxel_ - 0.5f,
              gz = (p.z - o.z) * inv_voxel_ - 0.5f;
  const float h = step_voxels;
  float v[6];
  if (!s.Trilinear(gx + h, gy, gz, &v[0], nullptr) ||
      !s.Trilinear(gx - h, gy, gz, &v[1], nullptr) ||
      !s.Trilinear(gx, gy + h, gz, &v[2], nullptr) ||
      !s.Trilinear(gx, gy - h, gz, &v[3], nullptr) ||
      !s.Trilinear(gx, gy, gz + h, &v[4], nullptr) ||
      !s.Trilinear(gx, gy, gz - h, &v[5], nullptr)) {
    return false;
  }
  const Vec3f g{v[0] - v[1], v[2] - v[3], v[4] - v[5]};
  const float len = Norm(g);
  if (!(len > 1e-6f)) return false;
  *normal = (1.0f / len) * g;
  return true;
}

void TsdfVolume::March(Vec3f origin, Vec3f dir, float t_min, float t_max, float* t_hit,
                       Vec3f* normal) const {
  *t_hit = 0;
  // Clip to the volume box (slabs).
  const Vec3f o = options_.origin;
  const float size = options_.size_m;
  float t0 = t_min, t1 = t_max;
  const float ro[3] = {origin.x - o.x, origin.y - o.y, origin.z - o.z};
  const float rd[3] = {dir.x, dir.y, dir.z};
  for (int a = 0; a < 3; ++a) {
    if (std::fabs(rd[a]) < 1e-12f) {
      if (ro[a] < 0 || ro[a] > size) return;
      continue;
    }
    float ta = -ro[a] / rd[a], tb = (size - ro[a]) / rd[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  if (t0 >= t1) return;
  const Sampler s{tsdf_.data(), res_, bricks_};
  const float mu = options_.truncation_m;
  const float brick_m = voxel_size_ * kBrick;
  const float inv_dir[3] = {1.0f / rd[0], 1.0f / rd[1], 1.0f / rd[2]};
  float t = t0 + 1e-5f;
  float prev_t = 0, prev_f = kNaN;
  while (t < t1) {
    const float px = ro[0] + t * rd[0], py = ro[1] + t * rd[1], pz = ro[2] + t * rd[2];
    const int i = static_cast<int>(px * inv_voxel_), j = static_cast<int>(py * inv_voxel_),
              k = static_cast<int>(pz * inv_voxel_);
    if (i < 0 || j < 0 || k < 0 || i >= res_ || j >= res_ || k >= res_) break;
    const size_t b = ((k >> 3) * bricks_ + (j >> 3)) * bricks_ + (i >> 3);
    if (!surface_[b]) {
      // Empty-space skipping: jump to where the ray leaves this brick, or its whole coarse cell
      // (kCoarse^3 bricks) when no brick of the cell holds a surface.
      float t_exit = t1;
      int bc[3] = {i >> 3, j >> 3, k >> 3};
      float cell_m = brick_m;
      const int ci = bc[0] / kCoarse, cj = bc[1] / kCoarse, ck = bc[2] / kCoarse;
      if (!coarse_[(static_cast<size_t>(ck) * coarse_side_ + cj) * coarse_side_ + ci]) {
        bc[0] = ci, bc[1] = cj, bc[2] = ck;
        cell_m = brick_m * kCoarse;
      }
      for (int a = 0; a < 3; ++a) {
        if (std::fabs(rd[a]) < 1e-12f) continue;
        const float bound = (rd[a] > 0 ? bc[a] + 1 : bc[a]) * cell_m;
        t_exit = std::min(t_exit, (bound - ro[a]) * inv_dir[a]);
      }
      t = std::max(t_exit, t) + 1e-4f;
      prev_f = kNaN;
      continue;
    }
    const size_t idx = (b << 9) | ((k & 7) << 6) | ((j & 7) << 3) | (i & 7);
    const float f = tsdf_[idx];
    if (f > kUnobservedTest) {
      prev_f = kNaN;
      t += 0.5f * mu;  // no surface can be here: the band around one is observed
      continue;
    }
    if (f < 0) {
      if (!(prev_f > 0)) {
        // The sample before was unobserved (frustum edges, unseen sides): accept a sample near
        // the surface, stepping back by its distance (at most one voxel); deep inside: no hit.
        if (f <= -0.9f) return;
        const float th = std::max(t - voxel_size_, t + f * mu);
        float v;
        Vec3f grad;
        auto g = [&](float tt, int a) { return (ro[a] + tt * rd[a]) * inv_voxel_ - 0.5f; };
        *normal = s.Trilinear(g(th, 0), g(th, 1), g(th, 2), &v, &grad) ? Normalized(grad)
                                                                       : Normalized(-1.0f * dir);
        if (Dot(*normal, dir) > 0) *normal = Normalized(-1.0f * dir);
        *t_hit = th;
        return;
      }
      // Zero crossing between prev_t and t: linear interpolation of the voxel values, then one
      // Newton step on the trilinear TSDF along the ray (KinectFusion §3.4), at most a voxel.
      float th = prev_t + (t - prev_t) * prev_f / (prev_f - f);
      auto g = [&](float tt, int a) { return (ro[a] + tt * rd[a]) * inv_voxel_ - 0.5f; };
      float v;
      Vec3f grad;
      if (s.Trilinear(g(th, 0), g(th, 1), g(th, 2), &v, &grad)) {
        const float slope = Dot(grad, dir) * inv_voxel_;  // d tsdf / d t, per metre
        if (slope < -1e-3f) {
          th -= std::clamp(v / slope, -voxel_size_, voxel_size_);
        }
        *normal = Normalized(grad);
      } else {
        *normal = Normalized(-1.0f * dir);
      }
      *t_hit = th;
      return;
    }
    prev_f = f;
    prev_t = t;
    t += std::max(voxel_size_, 0.8f * f * mu);
  }
}

void TsdfVolume::Raycast(const Pose& camera_to_world, const Intrinsics& k, GeometryView& out,
                         ThreadPool* pool) const {
  k.Validate("raycast");
  out.depth.Resize(k.width, k.height);
  out.normals.Resize(k.width, k.height);
  out.points.Resize(k.width, k.height);
  const RigidF c2w(camera_to_world);
  const RigidF w2c(camera_to_world.Inverse());
  const Vec3f cam = camera_to_world.Translation();
  // Range image: per 8 x 8-pixel tile the depth range [z_min, z_max] of the bricks near a
  // surface that project into it (bounding boxes of the projected brick corners).
  constexpr int kTile = 8;
  constexpr float kNear = 0.1f;
  const int tiles_x = (k.width + kTile - 1) / kTile, tiles_y = (k.height + kTile - 1) / kTile;
  std::vector<float> z_min(static_cast<size_t>(tiles_x) * tiles_y, 1e30f);
  std::vector<float> z_max(z_min.size(), 0.0f);
  const float brick_m = voxel_size_ * kBrick;
  const Vec3f o = options_.origin;
  for (size_t b = 0; b < surface_.size(); ++b) {
    if (!surface_[b]) continue;
    const int bi = static_cast<int>(b % bricks_), bj = static_cast<int>((b / bricks_) % bricks_),
              bk = static_cast<int>(b / (static_cast<size_t>(bricks_) * bricks_));
    float u0 = 1e30f, u1 = -1e30f, v0 = 1e30f, v1 = -1e30f, zlo = 1e30f, zhi = 0;
    bool behind = false;
    for (int c = 0; c < 8; ++c) {
      const Vec3f pw = o + Vec3f{(bi + (c & 1)) * brick_m, (bj + ((c >> 1) & 1)) * brick_m,
                                 (bk + (c >> 2)) * brick_m};
      const Vec3f pc = w2c.Apply(pw);
      zhi = std::max(zhi, pc.z);
      if (pc.z < kNear) {
        behind = true;
        continue;
      }
      zlo = std::min(zlo, pc.z);
      const float u = k.fx * pc.x / pc.z + k.cx, v = k.fy * pc.y / pc.z + k.cy;
      u0 = std::min(u0, u), u1 = std::max(u1, u), v0 = std::min(v0, v), v1 = std::max(v1, v);
    }
    if (zhi < kNear) continue;
    int tx0, tx1, ty0, ty1;
    if (behind) {  // straddles the camera plane: every tile, from the near plane
      zlo = kNear;
      tx0 = ty0 = 0;
      tx1 = tiles_x - 1;
      ty1 = tiles_y - 1;
    } else {
      if (u1 < -0.5f || v1 < -0.5f || u0 > k.width - 0.5f || v0 > k.height - 0.5f) continue;
      tx0 = std::max(0, static_cast<int>((u0 + 0.5f) / kTile));
      ty0 = std::max(0, static_cast<int>((v0 + 0.5f) / kTile));
      tx1 = std::min(tiles_x - 1, static_cast<int>((u1 + 0.5f) / kTile));
      ty1 = std::min(tiles_y - 1, static_cast<int>((v1 + 0.5f) / kTile));
    }
    for (int ty = ty0; ty <= ty1; ++ty)
      for (int tx = tx0; tx <= tx1; ++tx) {
        const size_t ti = static_cast<size_t>(ty) * tiles_x + tx;
        z_min[ti] = std::min(z_min[ti], zlo);
        z_max[ti] = std::max(z_max[ti], zhi);
      }
  }
  constexpr int kTasks = 32;
  ParallelFor(pool, kTasks, [&](int task) {
    for (int y = k.height * task / kTasks; y < k.height * (task + 1) / kTasks; ++y) {
      for (int x = 0; x < k.width; ++x) {
        const Vec3f ray{(x - k.cx) / k.fx, (y - k.cy) / k.fy, 1.0f};
        const float len = Norm(ray);
        const Vec3f dir_c = (1.0f / len) * ray;
        const size_t ti = static_cast<size_t>(y / kTile) * tiles_x + x / kTile;
        float t = 0;
        Vec3f n_w;
        if (z_max[ti] > 0) {
          // dir_c.z = 1 / len: t = z * len.
          March(cam, c2w.Rotate(dir_c), std::max(kNear, z_min[ti] - voxel_size_) * len,
                (z_max[ti] + voxel_size_) * len, &t, &n_w);
        }
        if (t > 0) {
          const Vec3f p = t * dir_c;
          out.depth.At(x, y) = p.z;
          out.points.At(x, y) = p;
          Vec3f n = w2c.Rotate(n_w);
          if (Dot(n, p) > 0) n = -1.0f * n;
          out.normals.At(x, y) = n;
        } else {
          out.depth.At(x, y) = 0;
          out.points.At(x, y) = {};
          out.normals.At(x, y) = {};
        }
      }
    }
  });
}

void TsdfVolume::RaycastOrthographic(const OrthographicView& view, GeometryView& out,
                                     ThreadPool* pool) const {
  if (view.width <= 0 || view.height <= 0 || !(view.pixel_size_m > 0)) {
    throw ReconError("raycast orthographic: width, height and pixel_size_m must be > 0");
  }
  out.depth.Resize(view.width, view.height);
  out.normals.Resize(view.width, view.height);
  out.points.Resize(view.width, view.height);
  const RigidF v2w(view.view_to_world);
  const RigidF w2v(view.view_to_world.Inverse());
  const Vec3f dir = v2w.Rotate({0, 0, 1});
  constexpr int kTasks = 32;
  ParallelFor(pool, kTasks, [&](int task) {
    for (int y = view.height * task / kTasks; y < view.height * (task + 1) / kTasks; ++y) {
      for (int x = 0; x < view.width; ++x) {
        const Vec3f pv{(x - (view.width - 1) * 0.5f) * view.pixel_size_m,
                       (y - (view.height - 1) * 0.5f) * view.pixel_size_m, 0};
        float t;
        Vec3f n_w;
        March(v2w.Apply(pv), dir, 0.0f, 1e3f, &t, &n_w);
        if (t > 0) {
          out.depth.At(x, y) = t;
          out.points.At(x, y) = {pv.x, pv.y, t};
          out.normals.At(x, y) = w2v.Rotate(n_w);
        } else {
          out.depth.At(x, y) = 0;
          out.points.At(x, y) = {};
          out.normals.At(x, y) = {};
        }
      }
    }
  });
}

namespace {
// A view whose axes are the given world directions (x, y, z columns), placed so that its z = 0
// plane is `half` before the volume centre along z, covering 2 * half with `pixels` pixels.
OrthographicView MakeView(Vec3f x, Vec3f y, Vec3f z, Vec3f centre, float half, int pixels) {
  OrthographicView v;
  const Vec3f axes[3] = {x, y, z};
  for (int c = 0; c < 3; ++c) {
    v.view_to_world.r[0 * 3 + c] = axes[c].x;
    v.view_to_world.r[1 * 3 + c] = axes[c].y;
    v.view_to_world.r[2 * 3 + c] = axes[c].z;
  }
  const Vec3f o = centre - half * z;
  v.view_to_world.t[0] = o.x;
  v.view_to_world.t[1] = o.y;
  v.view_to_world.t[2] = o.z;
  v.width = v.height = pixels;
  v.pixel_size_m = 2 * half / pixels;
  return v;
}
}  // namespace

AuxiliaryViews TsdfVolume::AuxiliaryViewsFor(const Pose& camera_to_world, int pixels) const {
  if (pixels <= 0) throw ReconError("auxiliary views: pixels must be > 0");
  const float half = options_.size_m * 0.5f * std::sqrt(3.0f);
  const Vec3f centre = options_.origin + Vec3f{options_.size_m * 0.5f, options_.size_m * 0.5f,
                                               options_.size_m * 0.5f};
  const Vec3f cx = camera_to_world.Rotate({1, 0, 0});
  const Vec3f cy = camera_to_world.Rotate({0, 1, 0});
  const Vec3f cz = camera_to_world.Rotate({0, 0, 1});
  AuxiliaryViews views;
  // Right-handed view frames (x = y cross z).
  views.left = MakeView(-1.0f * cz, cy, cx, centre, half, pixels);
  views.right = MakeView(cz, cy, -1.0f * cx, centre, half, pixels);
  views.top = MakeView(cx, -1.0f * cz, cy, centre, half, pixels);
  return views;
}

OrthographicView TsdfVolume::LightView(Vec3f direction, int pixels) const {
  if (pixels <= 0) throw ReconError("light view: pixels must be > 0");
  if (!std::isfinite(direction.x) || !std::isfinite(direction.y) || !std::isfinite(direction.z) ||
      Norm(direction) < 1e-6f) {
    throw ReconError("light view: direction must be finite and non-zero");
  }
  const Vec3f z = -1.0f * Normalized(direction);
  const Vec3f helper = std::fabs(z.y) < 0.9f ? Vec3f{0, 1, 0} : Vec3f{1, 0, 0};
  const Vec3f x = Normalized(Cross(helper, z));
  const Vec3f y = Cross(z, x);
  const float half = options_.size_m * 0.5f * std::sqrt(3.0f);
  const Vec3f centre = options_.origin + Vec3f{options_.size_m * 0.5f, options_.size_m * 0.5f,
                                               options_.size_m * 0.5f};
  return MakeView(x, y, z, centre, half, pixels);
}

Mesh TsdfVolume::ExtractMesh(ThreadPool* pool) const {
  std::vector<int> list;
  for (size_t b = 0; b < observed_.size(); ++b)
    if (observed_[b]) list.push_back(static_cast<int>(b));
  const int tasks = std::max(1, std::min<int>(64, static_cast<int>(list.size())));
  std::vector<Mesh> parts(tasks);
  const Vec3f o = options_.origin;
  // Six tetrahedra around the cube diagonal 0-7 (corner n = (n & 1, n >> 1 & 1, n >> 2)).
  static constexpr int kTets[6][4] = {{0, 7, 1, 3}, {0, 7, 3, 2}, {0, 7, 2, 6},
                                      {0, 7, 6, 4}, {0, 7, 4, 5}, {0, 7, 5, 1}};
  ParallelFor(pool, tasks, [&](int task) {
    Mesh& m = parts[task];
    const size_t n = list.size();
    for (size_t li = n * task / tasks; li < n * (task + 1) / tasks; ++li) {
      const int b = list[li];
      const int bi = b % bricks_, bj = (b / bricks_) % bricks_, bk = b / (bricks_ * bricks_);
      for (int vk = 0; vk < kBrick; ++vk)
        for (int vj = 0; vj < kBrick; ++vj)
          for (int vi = 0; vi < kBrick; ++vi) {
            const int i = bi * kBrick + vi, j = bj * kBrick + vj, k = bk * kBrick + vk;
            if (i + 1 >= res_ || j + 1 >= res_ || k + 1 >= res_) continue;
            float f[8];
            Vec3f p[8];
            bool ok = true, neg = false, pos = false;
            for (int c = 0; c < 8 && ok; ++c) {
              const int ci = i + (c & 1), cj = j + ((c >> 1) & 1), ck = k + (c >> 2);
              const size_t idx = VoxelIndex(ci, cj, ck);
              if (weight_[idx] == 0) ok = false;
              f[c] = tsdf_[idx];
              (f[c] < 0 ? neg : pos) = true;
              p[c] = o + Vec3f{(ci + 0.5f) * voxel_size_, (cj + 0.5f) * voxel_size_,
                               (ck + 0.5f) * voxel_size_};
            }
            if (!ok || !neg || !pos) continue;
            // Skip truncation walls (a jump from +1 to -1 is not a surface).
            float lo = 1, hi = -1;
            for (float v : f) lo = std::min(lo, v), hi = std::max(hi, v);
            if (hi - lo > 1.5f) continue;
            for (const auto& tet : kTets) {
              int in[4], out[4], ni = 0, no = 0;
              for (int c : tet) (f[c] < 0 ? in[ni++] : out[no++]) = c;
              if (ni == 0 || no == 0) continue;
              auto cut = [&](int a, int c) {
                return p[a] + (f[a] / (f[a] - f[c])) * (p[c] - p[a]);
              };
              Vec3f tri[2][3];
              int count = 0;
              if (ni == 1) {
                tri[0][0] = cut(in[0], out[0]);
                tri[0][1] = cut(in[0], out[1]);
                tri[0][2] = cut(in[0], out[2]);
                count = 1;
              } else if (no == 1) {
                tri[0][0] = cut(out[0], in[0]);
                tri[0][1] = cut(out[0], in[1]);
                tri[0][2] = cut(out[0], in[2]);
                count = 1;
              } else {
                const Vec3f a = cut(in[0], out[0]), bq = cut(in[0], out[1]), c = cut(in[1], out[1]),
                            d = cut(in[1], out[0]);
                tri[0][0] = a, tri[0][1] = bq, tri[0][2] = c;
                tri[1][0] = a, tri[1][1] = c, tri[1][2] = d;
                count = 2;
              }
              Vec3f cin{}, cout{};
              for (int q = 0; q < ni; ++q) cin = cin + p[in[q]];
              for (int q = 0; q < no; ++q) cout = cout + p[out[q]];
              const Vec3f towards_free = (1.0f / no) * cout - (1.0f / ni) * cin;
              for (int q = 0; q < count; ++q) {
                Vec3f nrm = Cross(tri[q][1] - tri[q][0], tri[q][2] - tri[q][0]);
                if (Dot(nrm, towards_free) < 0) {
                  std::swap(tri[q][1], tri[q][2]);
                  nrm = -1.0f * nrm;
                }
                nrm = Normalized(nrm);
                if (Norm(nrm) == 0) continue;
                for (int e = 0; e < 3; ++e) {
                  m.indices.push_back(static_cast<uint32_t>(m.vertices.size()));
                  m.vertices.push_back(tri[q][e]);
                  m.normals.push_back(nrm);
                }
              }
            }
          }
    }
  });
  Mesh mesh;
  for (const Mesh& part : parts) {
    const uint32_t base = static_cast<uint32_t>(mesh.vertices.size());
    mesh.vertices.insert(mesh.vertices.end(), part.vertices.begin(), part.vertices.end());
    mesh.normals.insert(mesh.normals.end(), part.normals.begin(), part.normals.end());
    for (uint32_t i : part.indices) mesh.indices.push_back(base + i);
  }
  return mesh;
}

void WritePly(const Mesh& mesh, const std::string& path) {
  std::ofstream f(path, std::ios::binary);
  if (!f) throw ReconError("mesh: cannot write '" + path + "'");
  f << "ply\nformat binary_little_endian 1.0\ncomment probeless recon TSDF mesh (metres)\n"
    << "element vertex " << mesh.vertices.size()
    << "\nproperty float x\nproperty float y\nproperty float z\n"
    << "property float nx\nproperty float ny\nproperty float nz\n"
    << "element face " << mesh.indices.size() / 3
    << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const float v[6] = {mesh.vertices[i].x, mesh.vertices[i].y, mesh.vertices[i].z,
                        mesh.normals[i].x,  mesh.normals[i].y,  mesh.normals[i].z};
    f.write(reinterpret_cast<const char*>(v), sizeof(v));
  }
  for (size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
    const uint8_t n = 3;
    f.write(reinterpret_cast<const char*>(&n), 1);
    const int32_t idx[3] = {static_cast<int32_t>(mesh.indices[t]),
                            static_cast<int32_t>(mesh.indices[t + 1]),
                            static_cast<int32_t>(mesh.indices[t + 2])};
    f.write(reinterpret_cast<const char*>(idx), sizeof(idx));
  }
  if (!f) throw ReconError("mesh: cannot write '" + path + "'");
}

}  // namespace probeless::recon
