// Light direction from cast shadows (docs/light.md, "Cast shadows"; shadow.h).
#include "probeless/light/shadow.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "parallel.h"
#include "shadow_kernel.h"

namespace probeless::light {
namespace {

struct Point {
  float x, y, z;      // camera frame, metres
  float nx, ny, nz;   // unit normal
  float intensity;    // linear grey
  int group;          // compact group index
  bool dark = false;  // observed dark: below mask_dark_ratio x its group's lit level
};

struct PointSet {
  std::vector<Point> points;
  int groups = 0;
  std::vector<double> sum_i, sum_ii;  // per group, independent of the direction
  std::vector<int> count;
  // The points' lattice (every stride-th pixel): cell (i, j) -> point index or -1.
  int grid_w = 0, grid_h = 0;
  std::vector<int> grid;
};

float SrgbToLinear(uint8_t v) {
  const float c = v / 255.0f;
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

// Cube-map face x 3 x 3 cells of a unit normal (54 bins).
int NormalBin(float nx, float ny, float nz) {
  const float ax = std::abs(nx), ay = std::abs(ny), az = std::abs(nz);
  int face;
  float a, b, m;
  if (ax >= ay && ax >= az) {
    face = nx > 0 ? 0 : 1, a = ny, b = nz, m = ax;
  } else if (ay >= az) {
    face = ny > 0 ? 2 : 3, a = nx, b = nz, m = ay;
  } else {
    face = nz > 0 ? 4 : 5, a = nx, b = ny, m = az;
  }
  const int ia = std::clamp(static_cast<int>((a / m + 1) * 1.5f), 0, 2);
  const int ib = std::clamp(static_cast<int>((b / m + 1) * 1.5f), 0, 2);
  return face * 9 + ia * 3 + ib;
}

PointSet CollectPoints(const GeometryView& g, std::span<const float> intensity,
                       std::span<const uint8_t> colour, int stride, const ShadowOptions& o) {
  std::vector<float> lut(256);
  for (int v = 0; v < 256; ++v) lut[v] = SrgbToLinear(static_cast<uint8_t>(v));
  const bool chroma = !colour.empty() && o.chroma_cells > 0;
  std::vector<Point> raw;
  std::vector<int> keys, cells;
  for (int v = stride / 2; v < g.height; v += stride) {
    for (int u = stride / 2; u < g.width; u += stride) {
      const size_t i = static_cast<size_t>(v) * g.width + u;
      const float z = g.depth[i];
      const float* n = &g.normals[3 * i];
      const float in = intensity[i];
      if (!(z > 0) || !std::isfinite(in) || (n[0] == 0 && n[1] == 0 && n[2] == 0)) continue;
      Point p;
      p.z = z;
      p.x = static_cast<float>((u - g.intrinsics.cx) / g.intrinsics.fx) * z;
      p.y = static_cast<float>((v - g.intrinsics.cy) / g.intrinsics.fy) * z;
      p.nx = n[0], p.ny = n[1], p.nz = n[2];
      p.intensity = std::clamp(in, 0.0f, 1.0f);
      int key = NormalBin(n[0], n[1], n[2]);
      if (chroma) {
        const float r = lut[colour[3 * i]], gg = lut[colour[3 * i + 1]], b = lut[colour[3 * i + 2]];
        const float s = r + gg + b;
        int cr = 0, cg = 0;
        if (s > 1e-4f) {
          cr = std::min(o.chroma_cells - 1, static_cast<int>(r / s * o.chroma_cells));
          cg = std::min(o.chroma_cells - 1, static_cast<int>(gg / s * o.chroma_cells));
        }
        key += 54 * (cr * o.chroma_cells + cg);
      }
      raw.push_back(p);
      keys.push_back(key);
      cells.push_back((v / stride) * (g.width / stride + 1) + u / stride);
    }
  }
  std::unordered_map<int, int> sizes;
  for (int k : keys) ++sizes[k];
  // Compact indices in order of first appearance (deterministic).
  std::unordered_map<int, int> index;
  PointSet set;
  set.grid_w = g.width / stride + 1;
  set.grid_h = g.height / stride + 1;
  set.grid.assign(static_cast<size_t>(set.grid_w) * set.grid_h, -1);
  for (size_t j = 0; j < raw.size(); ++j) {
    if (sizes[keys[j]] < o.min_group_points) continue;
    auto [it, inserted] = index.emplace(keys[j], set.groups);
    if (inserted) ++set.groups;
    raw[j].group = it->second;
    set.grid[cells[j]] = static_cast<int>(set.points.size());
    set.points.push_back(raw[j]);
  }
  // Observed shadow mask (direction-independent): a point is dark when its intensity is below
  // mask_dark_ratio x its group's lit level, the group's lit_quantile intensity (same
  // chromaticity and normal bin: same albedo and nearly the same n.l, less light).
  {
    std::vector<std::vector<float>> values(set.groups);
    for (const Point& p : set.points) values[p.group].push_back(p.intensity);
    std::vector<float> level(set.groups, 0);
    for (int gi = 0; gi < set.groups; ++gi) {
      auto& v = values[gi];
      const size_t k = std::min(v.size() - 1, static_cast<size_t>(o.lit_quantile * v.size()));
      std::nth_element(v.begin(), v.begin() + k, v.end());
      level[gi] = v[k];
    }
    for (Point& p : set.points) p.dark = p.intensity < o.mask_dark_ratio * level[p.group];
  }
  set.sum_i.assign(set.groups, 0);
  set.sum_ii.assign(set.groups, 0);
  set.count.assign(set.groups, 0);
  for (const Point& p : set.points) {
    set.sum_i[p.group] += p.intensity;
    set.sum_ii[p.group] += static_cast<double>(p.intensity) * p.intensity;
    ++set.count[p.group];
  }
  return set;
}

class Scorer {
 public:
  Scorer(const GeometryView& g, const ShadowOptions& o) : g_(g), o_(o) {
    const double q =
        std::pow(o.march_max_m / o.march_start_m, 1.0 / std::max(1, o.march_steps - 1));
    double t = o.march_start_m, prev = 0;
    for (int k = 0; k < o.march_steps; ++k) {
      steps_.push_back(static_cast<float>(t));
      thick_.push_back(std::max(o.thickness_m, o.thickness_steps * static_cast<float>(t - prev)));
      prev = t;
      t *= q;
    }
  }

  // 1 if the point sees the light along l (screen-space shadow ray), 0 if occluded, -1 if
  // unknown (with unknown_behind: the ray passed behind a surface by more than its thickness
  // and hit nothing).
  // The shadow ray (internal::ShadowRay8: 1 lit, 0 occluded, -1 unknown) of every point facing l
  // (n.l > 0), 8 points per kernel call; the others get 1. Score, Mask and Contrast all use it.
  void VisibleFacing(const PointSet& s, const Vec3f& l, std::vector<float>* vis) const {
    const size_t n = s.points.size();
    vis->assign(n, 1.0f);
    std::vector<int> facing;
    facing.reserve(n);
    for (size_t j = 0; j < n; ++j) {
      const Point& p = s.points[j];
      if (p.nx * l[0] + p.ny * l[1] + p.nz * l[2] > 0) facing.push_back(static_cast<int>(j));
    }
    const internal::ShadowRayParams ray = Ray();
    const internal::ShadowRay8Fn shadow_ray8 = internal::ShadowRay8Kernel();
    for (size_t i = 0; i < facing.size(); i += 8) {
      float x[8] = {}, y[8] = {}, z[8] = {}, out[8];
      const size_t m = std::min<size_t>(8, facing.size() - i);
      for (size_t k = 0; k < m; ++k) {
        const Point& p = s.points[facing[i + k]];
        x[k] = p.x, y[k] = p.y, z[k] = p.z;
      }
      shadow_ray8(ray, x, y, z, l, out);
      for (size_t k = 0; k < m; ++k) (*vis)[facing[i + k]] = out[k];
    }
  }

  // The explained fraction of the within-group variance (shadow.h), with or without shadows.
  // With the image cues (options.image_cues): a point observed dark that l predicts lit (its
  // darkness unexplained: possibly the shadow of an occluder out of view or missing from the
  // depth) weighs unexplained_dark_weight in the fit and in the total, and the score is
  // multiplied by min(1, b / boundary_ref), b the fraction of l's predicted shadow boundaries
  // seen in the image (Boundaries).
  float Score(const PointSet& s, const Vec3f& l, bool shadows) const {
    const bool cues = shadows && o_.image_cues;
    std::vector<double> sp(s.groups, 0), spp(s.groups, 0), sip(s.groups, 0);
    std::vector<double> si(s.sum_i), sii(s.sum_ii);  // the fit's sums of I, I^2 and weights
    std::vector<double> count(s.count.begin(), s.count.end());
    std::vector<double> ti(s.sum_i), tii(s.sum_ii);  // the total's (unknown points stay in it)
    std::vector<double> tn(s.count.begin(), s.count.end());
    std::vector<float> vis;  // per point: V for the boundaries, -1 = not counted
    if (cues) vis.assign(s.points.size(), -1.0f);
    std::vector<float> visible;  // V of the points facing l
    if (shadows) VisibleFacing(s, l, &visible);
    for (size_t j = 0; j < s.points.size(); ++j) {
      const Point& p = s.points[j];
      const float c = p.nx * l[0] + p.ny * l[1] + p.nz * l[2];
      if (c <= 0) continue;  // p = 0: adds nothing to the sums below
      const float v = shadows ? visible[j] : 1.0f;
      if (cues && c > o_.mask_min_cos) vis[j] = v;
      const double in = p.intensity;
      if (v < 0) {  // unknown: out of this direction's fit
        si[p.group] -= in;
        sii[p.group] -= in * in;
        --count[p.group];
        continue;
      }
      double w = 1;
      if (cues && v > 0 && p.dark) {
        w = o_.unexplained_dark_weight;
        const double drop = 1 - w;
        si[p.group] -= drop * in, ti[p.group] -= drop * in;
        sii[p.group] -= drop * in * in, tii[p.group] -= drop * in * in;
        count[p.group] -= drop, tn[p.group] -= drop;
      }
      const double x = c * v;
      sp[p.group] += w * x;
      spp[p.group] += w * x * x;
      sip[p.group] += w * x * in;
    }
    // The denominator is over all points: leaving unknown points out must not raise the score.
    double explained = 0, total = 0;
    for (int gi = 0; gi < s.groups; ++gi) {
      if (tn[gi] > 0.5) total += std::max(0.0, tii[gi] - ti[gi] * ti[gi] / tn[gi]);
      const double n = count[gi];
      if (n < 1.5) continue;
      const double syy = sii[gi] - si[gi] * si[gi] / n;
      const double sxx = spp[gi] - sp[gi] * sp[gi] / n;
      const double sxy = sip[gi] - sp[gi] * si[gi] / n;
      if (sxy > 0 && sxx > 1e-9 * n) explained += std::min(sxy * sxy / sxx, std::max(0.0, syy));
    }
    double factor = 1;
    if (cues && o_.boundary_ref > 0) {
      const auto [pairs, seen] = Boundaries(s, vis);
      factor = std::min(1.0, (seen + 1.0) / (pairs + 2.0) / o_.boundary_ref);
    }
    return total > 0 ? static_cast<float>(factor * explained / total) : 0.0f;
  }

  // Predicted shadow boundaries: 4-neighbours on the points' lattice, in one group, both with
  // known visibility (vis >= 0), one predicted lit and one shadowed. Returns their number and
  // how many of them the image shows: the lit one brighter than boundary_ratio x the shadowed one.
  std::pair<int, int> Boundaries(const PointSet& s, const std::vector<float>& vis) const {
    int pairs = 0, seen = 0;
    for (int gy = 0; gy < s.grid_h; ++gy) {
      for (int gx = 0; gx < s.grid_w; ++gx) {
        const int a = s.grid[gy * s.grid_w + gx];
        if (a < 0 || vis[a] < 0) continue;
        for (const int b : {gx + 1 < s.grid_w ? s.grid[gy * s.grid_w + gx + 1] : -1,
                            gy + 1 < s.grid_h ? s.grid[(gy + 1) * s.grid_w + gx] : -1}) {
          if (b < 0 || vis[b] < 0 || vis[a] == vis[b]) continue;
          if (s.points[a].group != s.points[b].group) continue;
          const float lit = s.points[vis[a] > 0 ? a : b].intensity;
          const float dark = s.points[vis[a] > 0 ? b : a].intensity;
          ++pairs;
          if (lit > o_.boundary_ratio * dark) ++seen;
        }
      }
    }
    return {pairs, seen};
  }

  // Predicted vs observed shadow mask under l (shadow.h, MaskAgreement), over the points with
  // n.l > mask_min_cos whose visibility is known.
  MaskAgreement Mask(const PointSet& s, const Vec3f& l) const {
    std::vector<float> vis(s.points.size(), -1.0f), visible;
    VisibleFacing(s, l, &visible);  // as Score computes it (mask_min_cos >= 0: facing points)
    int predicted = 0, observed = 0, both = 0;
    for (size_t j = 0; j < s.points.size(); ++j) {
      const Point& p = s.points[j];
      if (p.nx * l[0] + p.ny * l[1] + p.nz * l[2] <= o_.mask_min_cos) continue;
      vis[j] = visible[j];
      if (vis[j] < 0) continue;
      predicted += vis[j] == 0 ? 1 : 0;
      observed += p.dark ? 1 : 0;
      both += vis[j] == 0 && p.dark ? 1 : 0;
    }
    MaskAgreement m;
    m.predicted = predicted;
    m.observed = observed;
    m.precision = predicted > 0 ? static_cast<float>(both) / predicted : 0.0f;
    m.recall = observed > 0 ? static_cast<float>(both) / observed : 0.0f;
    const auto [pairs, seen] = Boundaries(s, vis);
    m.boundaries = pairs;
    m.boundary_precision = pairs > 0 ? static_cast<float>(seen) / pairs : 0.0f;
    return m;
  }

  // Lit / shadowed contrast under l: exp of the mean over groups (weighted by the smaller side's
  // point count) of log(mean lit intensity / mean shadowed intensity), over front-facing points;
  // 1 when no group has at least 3 points on each side.
  float Contrast(const PointSet& s, const Vec3f& l) const {
    std::vector<double> lit(s.groups, 0), dark(s.groups, 0);
    std::vector<int> n_lit(s.groups, 0), n_dark(s.groups, 0);
    std::vector<float> visible;
    VisibleFacing(s, l, &visible);  // as Score computes it
    for (size_t j = 0; j < s.points.size(); ++j) {
      const Point& p = s.points[j];
      const float c = p.nx * l[0] + p.ny * l[1] + p.nz * l[2];
      if (c <= 0.1f) continue;
      const float v = visible[j];
      if (v < 0) continue;
      if (v > 0) {
        lit[p.group] += p.intensity, ++n_lit[p.group];
      } else {
        dark[p.group] += p.intensity, ++n_dark[p.group];
      }
    }
    double sum = 0, weight = 0;
    for (int gi = 0; gi < s.groups; ++gi) {
      if (n_lit[gi] < 3 || n_dark[gi] < 3) continue;
      const double a = lit[gi] / n_lit[gi], b = dark[gi] / n_dark[gi];
      if (!(a > 0) || !(b > 0)) continue;
      const double w = std::min(n_lit[gi], n_dark[gi]);
      sum += w * std::log(a / b);
      weight += w;
    }
    return weight > 0 ? static_cast<float>(std::exp(sum / weight)) : 1.0f;
  }

 private:
  internal::ShadowRayParams Ray() const {
    internal::ShadowRayParams r;
    r.depth = g_.depth.data();
    r.width = g_.width, r.height = g_.height;
    r.fx = static_cast<float>(g_.intrinsics.fx), r.fy = static_cast<float>(g_.intrinsics.fy);
    r.cx = static_cast<float>(g_.intrinsics.cx), r.cy = static_cast<float>(g_.intrinsics.cy);
    r.steps = steps_.data(), r.thickness = thick_.data();
    r.step_count = static_cast<int>(steps_.size());
    r.bias = o_.depth_bias_m, r.bias_rel = o_.depth_bias_rel;
    r.unknown_behind = o_.unknown_behind;
    return r;
  }
  const GeometryView& g_;
  const ShadowOptions& o_;
  std::vector<float> steps_, thick_;
};

Vec3f Normalised(double x, double y, double z) {
  const double n = std::sqrt(x * x + y * y + z * z);
  return {static_cast<float>(x / n), static_cast<float>(y / n), static_cast<float>(z / n)};
}

float Dot(const Vec3f& a, const Vec3f& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// Scores all directions (in parallel; each score is computed by one thread alone).
std::vector<float> ScoreAll(const Scorer& scorer, const PointSet& s, const std::vector<Vec3f>& dirs,
                            int threads) {
  std::vector<float> out(dirs.size());
  internal::ParallelRows(threads, static_cast<int>(dirs.size()), 1, [&](int b, int e) {
    for (int j = b; j < e; ++j) out[j] = scorer.Score(s, dirs[j], true);
  });
  return out;
}

void Check(const GeometryView& g, std::span<const float> intensity, std::span<const uint8_t> colour,
           const ShadowOptions& o) {
  const std::string f = "light::EstimateShadowDirection: ";
  const size_t n = static_cast<size_t>(std::max(0, g.width)) * std::max(0, g.height);
  if (g.width <= 0 || g.height <= 0) throw LightError(f + "empty geometry");
  if (g.depth.size() != n) {
    throw LightError(f + "depth has " + std::to_string(g.depth.size()) + " values, expected " +
                     std::to_string(g.width) + "x" + std::to_string(g.height));
  }
  if (g.normals.size() != 3 * n) throw LightError(f + "missing normals");
  if (intensity.size() != n) {
    throw LightError(f + "intensity has " + std::to_string(intensity.size()) +
                     " values, expected " + std::to_string(n));
  }
  if (!colour.empty() && colour.size() != 3 * n) {
    throw LightError(f + "colour has " + std::to_string(colour.size()) + " bytes, expected " +
                     std::to_string(3 * n));
  }
  const Intrinsics& k = g.intrinsics;
  if (!std::isfinite(k.fx) || !std::isfinite(k.fy) || !std::isfinite(k.cx) ||
      !std::isfinite(k.cy) || k.fx <= 0 || k.fy <= 0) {
    throw LightError(f + "non-finite intrinsics");
  }
  const std::pair<bool, const char*> rules[] = {
      {o.coarse_stride >= 1 && o.stride >= 1, "strides must be >= 1"},
      {o.coarse_directions >= 16 && o.coarse_directions <= 1024,
       "coarse_directions must be in 16..1024"},
      {o.candidates >= 1, "candidates must be >= 1"},
      {o.refine_levels >= 0 && o.refine_start_deg > 0,
       "refine_levels must be >= 0 and refine_start_deg > 0"},
      {o.march_steps >= 1 && o.march_start_m > 0 && o.march_max_m > o.march_start_m,
       "march_steps must be >= 1 and 0 < march_start_m < march_max_m"},
      {o.chroma_cells >= 0 && o.min_group_points >= 2,
       "chroma_cells must be >= 0 and min_group_points >= 2"},
      {o.threads >= 1, "threads must be >= 1"},
      {o.mask_dark_ratio > 0 && o.mask_dark_ratio < 1 && o.lit_quantile >= 0 && o.lit_quantile <= 1,
       "mask_dark_ratio must be in (0, 1) and lit_quantile in [0, 1]"},
      {o.unexplained_dark_weight >= 0 && o.unexplained_dark_weight <= 1,
       "unexplained_dark_weight must be in [0, 1]"},
      {o.boundary_ratio > 1 && o.boundary_ref > 0 && o.boundary_ref <= 1,
       "boundary_ratio must be > 1 and boundary_ref in (0, 1]"},
      {o.keep_ratio >= 0 && o.keep_ratio <= 1 && o.cue_keep_ratio >= 0 && o.cue_keep_ratio <= 1,
       "keep_ratio and cue_keep_ratio must be in [0, 1]"},
      {o.mask_min_cos >= 0 && o.mask_min_cos < 1, "mask_min_cos must be in [0, 1)"},
  };
  for (const auto& [ok, message] : rules) {
    if (!ok) throw LightError(f + message);
  }
}

}  // namespace

ShadowEstimate EstimateShadowDirection(const GeometryView& g, std::span<const float> intensity,
                                       const ShadowOptions& o, std::span<const uint8_t> colour,
                                       const Vec3f* initial) {
  Check(g, intensity, colour, o);
  ShadowEstimate out;
  const Scorer scorer(g, o);
  // Global pass: Fibonacci directions over the sphere (+ the initial direction).
  const PointSet coarse = CollectPoints(g, intensity, colour, o.coarse_stride, o);
  if (coarse.groups == 0) return out;
  std::vector<Vec3f> dirs;
  const double golden = std::numbers::pi * (3 - std::sqrt(5.0));
  for (int j = 0; j < o.coarse_directions; ++j) {
    const double z = 1 - (2 * j + 1.0) / o.coarse_directions;
    const double r = std::sqrt(std::max(0.0, 1 - z * z));
    dirs.push_back(Normalised(r * std::cos(golden * j), r * std::sin(golden * j), z));
  }
  if (initial != nullptr && Dot(*initial, *initial) > 0.5f) dirs.push_back(*initial);
  const std::vector<float> scores = ScoreAll(scorer, coarse, dirs, o.threads);
  out.evaluations += static_cast<int>(dirs.size());
  std::vector<int> order(dirs.size());
  for (size_t j = 0; j < order.size(); ++j) order[j] = static_cast<int>(j);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return scores[a] > scores[b]; });
  std::vector<Vec3f> seeds;
  for (int j : order) {
    if (static_cast<int>(seeds.size()) >= o.candidates) break;
    bool apart = true;
    for (const Vec3f& s : seeds)
      apart = apart && Dot(s, dirs[j]) < std::cos(20 * std::numbers::pi / 180);
    if (apart) seeds.push_back(dirs[j]);
  }
  // Refinement: a 3 x 3 pattern in the tangent plane, step halved per level.
  const PointSet fine = CollectPoints(g, intensity, colour, o.stride, o);
  out.points = static_cast<int>(fine.points.size());
  out.groups = fine.groups;
  if (fine.groups == 0) return out;
  float best_score = -1, runner_up = -1;
  Vec3f best{0, 0, 1};
  // Each seed is refined by one thread when there are enough seeds (no synchronisation per
  // level); otherwise each level's ring is scored in parallel. Same scores either way.
  const int seed_threads = std::min<int>(o.threads, static_cast<int>(seeds.size()));
  const int ring_threads = seed_threads > 1 ? 1 : o.threads;
  std::vector<std::pair<Vec3f, float>> refined(seeds.size());
  std::vector<int> evaluations(seeds.size(), 0);
  internal::ParallelRows(seed_threads, static_cast<int>(seeds.size()), 1, [&](int b, int e) {
    for (int k = b; k < e; ++k) {
      Vec3f d = seeds[k];
      float s = scorer.Score(fine, d, true);
      ++evaluations[k];
      double step = o.refine_start_deg * std::numbers::pi / 180;
      for (int level = 0; level < o.refine_levels; ++level, step *= 0.5) {
        // Tangent basis at d.
        const Vec3f a = std::abs(d[0]) < 0.9f ? Vec3f{1, 0, 0} : Vec3f{0, 1, 0};
        Vec3f e1 = Normalised(a[1] * d[2] - a[2] * d[1], a[2] * d[0] - a[0] * d[2],
                              a[0] * d[1] - a[1] * d[0]);
        Vec3f e2 = Normalised(d[1] * e1[2] - d[2] * e1[1], d[2] * e1[0] - d[0] * e1[2],
                              d[0] * e1[1] - d[1] * e1[0]);
        std::vector<Vec3f> ring;
        for (int i = -1; i <= 1; ++i) {
          for (int j = -1; j <= 1; ++j) {
            if (i == 0 && j == 0) continue;
            if (i != 0 && j != 0) continue;  // compass search: 4 neighbours
            const double ti = std::tan(i * step), tj = std::tan(j * step);
            ring.push_back(Normalised(d[0] + ti * e1[0] + tj * e2[0],
                                      d[1] + ti * e1[1] + tj * e2[1],
                                      d[2] + ti * e1[2] + tj * e2[2]));
          }
        }
        const std::vector<float> rs = ScoreAll(scorer, fine, ring, ring_threads);
        evaluations[k] += static_cast<int>(ring.size());
        for (size_t j = 0; j < ring.size(); ++j) {
          if (rs[j] > s) s = rs[j], d = ring[j];
        }
      }
      refined[k] = {d, s};
    }
  });
  for (size_t k = 0; k < seeds.size(); ++k) {
    out.evaluations += evaluations[k];
    if (refined[k].second > best_score) best_score = refined[k].second, best = refined[k].first;
  }
  // Runner-up: the best refined candidate that did not converge to the best direction.
  for (const auto& [d, s] : refined) {
    if (Dot(d, best) < std::cos(20 * std::numbers::pi / 180)) runner_up = std::max(runner_up, s);
  }
  out.score = best_score;
  out.runner_up = std::max(0.0f, runner_up);
  out.score_unshadowed = scorer.Score(fine, best, false);
  out.contrast = scorer.Contrast(fine, best);
  out.valid = out.score >= o.min_score && out.score - out.score_unshadowed >= o.min_gain &&
              out.contrast >= o.min_contrast && out.runner_up <= o.max_runner_up * out.score;
  out.direction = best;
  // The direction closest to `initial` on the arc towards `best` that explains the shadows
  // nearly as well (score >= keep_ratio x best): the shadows correct the initial direction only
  // as far as they contradict it.
  const float keep_ratio = o.image_cues ? o.cue_keep_ratio : o.keep_ratio;
  if (out.valid && initial != nullptr && Dot(*initial, *initial) > 0.5f && keep_ratio > 0) {
    const Vec3f from = Normalised((*initial)[0], (*initial)[1], (*initial)[2]);
    auto along = [&](double f) {  // slerp-like: normalised linear blend (angles < 180 deg)
      return Normalised(from[0] + f * (best[0] - from[0]), from[1] + f * (best[1] - from[1]),
                        from[2] + f * (best[2] - from[2]));
    };
    const float need = keep_ratio * best_score;
    if (Dot(from, best) > -0.9f) {
      if (scorer.Score(fine, from, true) >= need) {
        out.direction = from;
      } else {
        double lo = 0, hi = 1;  // score(along(hi)) >= need
        for (int it = 0; it < 5; ++it) {
          const double mid = 0.5 * (lo + hi);
          (scorer.Score(fine, along(mid), true) >= need ? hi : lo) = mid;
        }
        out.direction = along(hi);
        out.evaluations += 5;
      }
      ++out.evaluations;
    }
  }
  return out;
}

float ShadowScore(const GeometryView& g, std::span<const float> intensity,
                  const ShadowOptions& options, std::span<const uint8_t> colour,
                  const Vec3f& direction, bool shadows) {
  Check(g, intensity, colour, options);
  const Scorer scorer(g, options);
  const PointSet set = CollectPoints(g, intensity, colour, options.stride, options);
  return scorer.Score(set, Normalised(direction[0], direction[1], direction[2]), shadows);
}

MaskAgreement ShadowMaskAgreement(const GeometryView& g, std::span<const float> intensity,
                                  const ShadowOptions& options, std::span<const uint8_t> colour,
                                  const Vec3f& direction) {
  Check(g, intensity, colour, options);
  const Scorer scorer(g, options);
  const PointSet set = CollectPoints(g, intensity, colour, options.stride, options);
  return scorer.Mask(set, Normalised(direction[0], direction[1], direction[2]));
}

ShadowOptions RawDepthShadowOptions(ShadowOptions base) {
  base.image_cues = true;
  return base;
}

void RotateLightTo(const Vec3f& direction, LightEstimate* light) {
  if (light == nullptr || !light->valid) return;
  const Vec3f to = Normalised(direction[0], direction[1], direction[2]);
  const Vec3f& from = light->dominant_direction;
  if (Dot(from, from) < 0.5f || light->bands < 1) {
    light->dominant_direction = to;
    return;
  }
  // R maps `to` onto `from` (ShRotationMatrix: l = A l' is the function f(d) = f'(R d), whose
  // peak moves from `from` to R^T from = `to`). Rodrigues with axis to x from.
  const Vec3f f = Normalised(from[0], from[1], from[2]);
  const double c = Dot(to, f);
  double ax = to[1] * f[2] - to[2] * f[1], ay = to[2] * f[0] - to[0] * f[2],
         az = to[0] * f[1] - to[1] * f[0];
  const double s = std::sqrt(ax * ax + ay * ay + az * az);
  std::array<float, 9> r{1, 0, 0, 0, 1, 0, 0, 0, 1};
  if (s > 1e-7) {
    ax /= s, ay /= s, az /= s;
    const double k[9] = {0, -az, ay, az, 0, -ax, -ay, ax, 0};
    double k2[9];
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        k2[3 * i + j] = 0;
        for (int m = 0; m < 3; ++m) k2[3 * i + j] += k[3 * i + m] * k[3 * m + j];
      }
    }
    for (int i = 0; i < 9; ++i) r[i] = static_cast<float>(r[i] + s * k[i] + (1 - c) * k2[i]);
  } else if (c < 0) {
    // Opposite: 180 degrees about any axis perpendicular to `to`.
    const Vec3f a = std::abs(to[0]) < 0.9f ? Vec3f{1, 0, 0} : Vec3f{0, 1, 0};
    const Vec3f p = Normalised(a[1] * to[2] - a[2] * to[1], a[2] * to[0] - a[0] * to[2],
                               a[0] * to[1] - a[1] * to[0]);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) r[3 * i + j] = 2 * p[i] * p[j] - (i == j ? 1.0f : 0.0f);
    }
  }
  std::vector<double> a;
  ShRotationMatrix(r.data(), light->bands, &a);
  const size_t n = light->coefficients.size();
  std::vector<double> rotated(n, 0);
  for (size_t i = 0; i < n; ++i) {
    for (size_t j = 0; j < n; ++j) rotated[i] += a[i * n + j] * light->coefficients[j];
  }
  light->coefficients = rotated;
  light->dominant_direction = to;
}

ShadowEstimate RefineLightWithShadows(const GeometryView& g, std::span<const float> intensity,
                                      const ShadowOptions& options, std::span<const uint8_t> colour,
                                      LightEstimate* light) {
  const bool seeded = light != nullptr && light->valid &&
                      Dot(light->dominant_direction, light->dominant_direction) > 0.5f;
  ShadowEstimate s = EstimateShadowDirection(g, intensity, options, colour,
                                             seeded ? &light->dominant_direction : nullptr);
  if (s.valid && light != nullptr) RotateLightTo(s.direction, light);
  return s;
}

}  // namespace probeless::light
