#include "probeless/recon/icp.h"

#include <algorithm>
#include <cmath>
#include <iterator>

namespace probeless::recon {

void BuildModelPyramid(const GeometryView& view, const Pose& camera_to_world,
                       const Intrinsics& intrinsics, int levels, ModelPyramid& out) {
  out.camera_to_world = camera_to_world;
  out.intrinsics.resize(levels);
  out.points.resize(levels);
  out.normals.resize(levels);
  for (int l = 0; l < levels; ++l) {
    out.intrinsics[l] = intrinsics.Level(l);
    if (l == 0) {
      out.points[0] = view.points;
      out.normals[0] = view.normals;
      continue;
    }
    const Vec3Image& ps = out.points[l - 1];
    const Vec3Image& ns = out.normals[l - 1];
    out.points[l].Resize(ps.width / 2, ps.height / 2);
    out.normals[l].Resize(ps.width / 2, ps.height / 2);
    for (int y = 0; y < ps.height / 2; ++y)
      for (int x = 0; x < ps.width / 2; ++x) {
        out.points[l].At(x, y) = ps.At(2 * x, 2 * y);
        out.normals[l].At(x, y) = ns.At(2 * x, 2 * y);
      }
  }
}

namespace {
// Upper triangle of J^T J (21), J^T r (6), sum r^2, count.
struct Accum {
  double a[21] = {};
  double b[6] = {};
  double r2 = 0;
  int n = 0;
};

// Solves A x = b (6x6 symmetric positive definite) by Cholesky; false if not positive definite.
// `condition` = smallest / largest diagonal pivot.
bool SolveCholesky(const double a_upper[21], const double b[6], double x[6], double* condition) {
  double a[6][6];
  int idx = 0;
  for (int i = 0; i < 6; ++i)
    for (int j = i; j < 6; ++j) a[i][j] = a[j][i] = a_upper[idx++];
  double l[6][6] = {};
  double pmin = 1e300, pmax = 0;
  for (int j = 0; j < 6; ++j) {
    double s = a[j][j];
    for (int k = 0; k < j; ++k) s -= l[j][k] * l[j][k];
    if (!(s > 0)) return false;
    pmin = std::min(pmin, s);
    pmax = std::max(pmax, s);
    l[j][j] = std::sqrt(s);
    for (int i = j + 1; i < 6; ++i) {
      double t = a[i][j];
      for (int k = 0; k < j; ++k) t -= l[i][k] * l[j][k];
      l[i][j] = t / l[j][j];
    }
  }
  double y[6];
  for (int i = 0; i < 6; ++i) {
    double s = b[i];
    for (int k = 0; k < i; ++k) s -= l[i][k] * y[k];
    y[i] = s / l[i][i];
  }
  for (int i = 5; i >= 0; --i) {
    double s = y[i];
    for (int k = i + 1; k < 6; ++k) s -= l[k][i] * x[k];
    x[i] = s / l[i][i];
  }
  *condition = pmin / pmax;
  return true;
}

constexpr int kTasks = 16;

// ICP's projective association at one relative pose (frame camera -> model camera), level 0.
struct Association {
  float r[9], t[3];
  const Vec3Image* points;
  const Vec3Image* normals;
  Intrinsics k;
  float dmax2, cos_max;

  // The frame point v with normal nv (frame camera) finds a model pair: the gates of TrackIcp.
  bool Pairs(Vec3f v, Vec3f nv) const {
    const Vec3f p{r[0] * v.x + r[1] * v.y + r[2] * v.z + t[0],
                  r[3] * v.x + r[4] * v.y + r[5] * v.z + t[1],
                  r[6] * v.x + r[7] * v.y + r[8] * v.z + t[2]};
    if (p.z <= 0) return false;
    const int w = points->width, h = points->height;
    const float uf = k.fx * p.x / p.z + k.cx, vf = k.fy * p.y / p.z + k.cy;
    if (!(uf >= -0.5f && uf < w - 0.5f && vf >= -0.5f && vf < h - 0.5f)) return false;
    const int u = static_cast<int>(uf + 0.5f), vv = static_cast<int>(vf + 0.5f);
    const Vec3f q = points->At(u, vv), nq = normals->At(u, vv);
    if (q.z <= 0 || (nq.x == 0 && nq.y == 0 && nq.z == 0)) return false;
    const Vec3f d = p - q;
    if (Dot(d, d) > dmax2) return false;
    const Vec3f nr{r[0] * nv.x + r[1] * nv.y + r[2] * nv.z, r[3] * nv.x + r[4] * nv.y + r[5] * nv.z,
                   r[6] * nv.x + r[7] * nv.y + r[8] * nv.z};
    return Dot(nr, nq) >= cos_max;
  }
};

// The point-to-plane normal matrix of the frame's own geometry, one pair per block x block
// pixels: the block's mean point and its renormalised mean normal (blocks with fewer than half
// of their pixels valid, or whose normals cancel - a crease - are skipped). Averaging divides the
// normals' noise variance, which otherwise shows as a constraint in every direction (a floor and
// a wall seen through Kinect-like noise look as constrained along their intersection as a real
// kitchen's weakest direction), while piecewise-planar geometry keeps its normals.
// `match` (nullptr: every pixel): only the samples that find a model pair count, so the matrix
// describes the part of the frame that constrains ICP's estimate.
void FrameNormalEquations(const Vec3Image& vs, const Vec3Image& ns, int block,
                          const Association* match, double normal_equations[21], int* pairs,
                          float* mean_depth_m, ThreadPool* pool) {
  const int bw = vs.width / block, bh = vs.height / block;
  // Per task in fixed rows of blocks, summed in task order: deterministic for any thread count.
  struct Sum {
    double a[21] = {};
    double depth = 0;
    int pairs = 0;
  };
  Sum sums[kTasks];
  ParallelFor(pool, kTasks, [&](int task) {
    Sum& sum = sums[task];
    for (int by = bh * task / kTasks; by < bh * (task + 1) / kTasks; ++by)
      for (int bx = 0; bx < bw; ++bx) {
        Vec3f p{}, n{};
        int count = 0;
        // Every second pixel each way: neighbouring normals share their depth samples, so the
        // other three add little averaging for four times the cost.
        for (int y = by * block; y < (by + 1) * block; y += 2)
          for (int x = bx * block; x < (bx + 1) * block; x += 2) {
            const Vec3f v = vs.At(x, y), nv = ns.At(x, y);
            if (v.z <= 0 || (nv.x == 0 && nv.y == 0 && nv.z == 0)) continue;
            if (match != nullptr && !match->Pairs(v, nv)) continue;
            p = p + v;
            n = n + nv;
            ++count;
          }
        const int samples = ((block + 1) / 2) * ((block + 1) / 2);
        if (2 * count < samples || Norm(n) < 0.5f * count) continue;
        p = (1.0f / count) * p;
        n = Normalized(n);
        const Vec3f c = Cross(p, n);
        const double j[6] = {c.x, c.y, c.z, n.x, n.y, n.z};
        int idx = 0;
        for (int i0 = 0; i0 < 6; ++i0)
          for (int i1 = i0; i1 < 6; ++i1) sum.a[idx++] += j[i0] * j[i1];
        sum.depth += p.z;
        ++sum.pairs;
      }
  });
  std::fill(normal_equations, normal_equations + 21, 0.0);
  *pairs = 0;
  double depth_sum = 0;
  for (const Sum& sum : sums) {
    for (int i = 0; i < 21; ++i) normal_equations[i] += sum.a[i];
    depth_sum += sum.depth;
    *pairs += sum.pairs;
  }
  *mean_depth_m = *pairs > 0 ? static_cast<float>(depth_sum / *pairs) : 0.0f;
}
}  // namespace

IcpResult TrackIcp(const FramePyramid& frame, const ModelPyramid& model, const Pose& initial,
                   const IcpOptions& options, ThreadPool* pool) {
  // Model level l pairs with frame level offset + l (the frame may hold finer, untracked levels).
  const int levels = static_cast<int>(model.points.size());
  const int offset = static_cast<int>(frame.vertices.size()) - levels;
  if (levels == 0 || offset < 0 || static_cast<int>(options.iterations.size()) < levels) {
    throw ReconError("icp: frame, model and iteration levels differ (" +
                     std::to_string(frame.vertices.size()) + ", " +
                     std::to_string(model.points.size()) + ", " +
                     std::to_string(options.iterations.size()) + ")");
  }
  if (options.observability_block < 1) {
    throw ReconError("icp: observability_block must be >= 1, got " +
                     std::to_string(options.observability_block));
  }
  for (int l = 0; l < levels; ++l) {
    if (frame.vertices[offset + l].width != model.points[l].width ||
        frame.vertices[offset + l].height != model.points[l].height) {
      throw ReconError("icp: frame and model sizes differ at level " + std::to_string(l));
    }
  }
  IcpResult result;
  result.camera_to_world = initial;
  const Pose world_to_model = model.camera_to_world.Inverse();
  // The relative pose current camera -> model camera, refined in place.
  Pose rel = world_to_model * initial;
  const float cos_max = std::cos(options.max_angle_deg * 3.14159265f / 180.0f);
  const float dmax2 = options.max_distance_m * options.max_distance_m;
  double condition = 1;
  Accum last;
  int valid0 = 0;
  for (const Vec3f& v : frame.vertices[offset].data) valid0 += v.z > 0;
  FrameNormalEquations(frame.vertices[offset], frame.normals[offset], options.observability_block,
                       nullptr, result.normal_equations, &result.pairs, &result.mean_depth_m, pool);
  for (int l = levels - 1; l >= 0; --l) {
    const Vec3Image& vs = frame.vertices[offset + l];
    const Vec3Image& ns = frame.normals[offset + l];
    const Vec3Image& mp = model.points[l];
    const Vec3Image& mn = model.normals[l];
    const Intrinsics& k = model.intrinsics[l];
    const int w = vs.width, h = vs.height;
    for (int it = 0; it < options.iterations[l]; ++it) {
      ++result.iterations;
      float r[9], t[3];
      for (int i = 0; i < 9; ++i) r[i] = static_cast<float>(rel.r[i]);
      for (int i = 0; i < 3; ++i) t[i] = static_cast<float>(rel.t[i]);
      Accum acc[kTasks];
      ParallelFor(pool, kTasks, [&](int task) {
        Accum& out = acc[task];
        // Float partial sums per row, double across rows.
        for (int y = h * task / kTasks; y < h * (task + 1) / kTasks; ++y) {
          float a[21] = {}, b[6] = {}, r2 = 0;
          int n = 0;
          for (int x = 0; x < w; ++x) {
            const Vec3f v = vs.At(x, y);
            const Vec3f nv = ns.At(x, y);
            if (v.z <= 0 || (nv.x == 0 && nv.y == 0 && nv.z == 0)) continue;
            const Vec3f p{r[0] * v.x + r[1] * v.y + r[2] * v.z + t[0],
                          r[3] * v.x + r[4] * v.y + r[5] * v.z + t[1],
                          r[6] * v.x + r[7] * v.y + r[8] * v.z + t[2]};
            if (p.z <= 0) continue;
            const float uf = k.fx * p.x / p.z + k.cx, vf = k.fy * p.y / p.z + k.cy;
            if (!(uf >= -0.5f && uf < w - 0.5f && vf >= -0.5f && vf < h - 0.5f)) continue;
            const int u = static_cast<int>(uf + 0.5f), vv = static_cast<int>(vf + 0.5f);
            const Vec3f q = mp.At(u, vv);
            const Vec3f nq = mn.At(u, vv);
            if (q.z <= 0 || (nq.x == 0 && nq.y == 0 && nq.z == 0)) continue;
            const Vec3f d = p - q;
            if (Dot(d, d) > dmax2) continue;
            const Vec3f nr{r[0] * nv.x + r[1] * nv.y + r[2] * nv.z,
                           r[3] * nv.x + r[4] * nv.y + r[5] * nv.z,
                           r[6] * nv.x + r[7] * nv.y + r[8] * nv.z};
            if (Dot(nr, nq) < cos_max) continue;
            // Residual e = n_q . (p - q); d e / d(w, t) = (p x n_q, n_q) (eq. 16-18, linearised
            // about the current estimate, update applied on the left).
            const float e = Dot(nq, d);
            const Vec3f c = Cross(p, nq);
            const float j[6] = {c.x, c.y, c.z, nq.x, nq.y, nq.z};
            int idx = 0;
            for (int i0 = 0; i0 < 6; ++i0) {
              for (int i1 = i0; i1 < 6; ++i1) a[idx++] += j[i0] * j[i1];
              b[i0] += j[i0] * e;
            }
            r2 += e * e;
            ++n;
          }
          for (int i = 0; i < 21; ++i) out.a[i] += a[i];
          for (int i = 0; i < 6; ++i) out.b[i] += b[i];
          out.r2 += r2;
          out.n += n;
        }
      });
      Accum sum;
      for (const Accum& a : acc) {
        for (int i = 0; i < 21; ++i) sum.a[i] += a.a[i];
        for (int i = 0; i < 6; ++i) sum.b[i] += a.b[i];
        sum.r2 += a.r2;
        sum.n += a.n;
      }
      last = sum;
      if (sum.n < 6) {
        result.failure = "too few correspondences (" + std::to_string(sum.n) + ")";
        return result;
      }
      double neg_b[6], xi[6];
      for (int i = 0; i < 6; ++i) neg_b[i] = -sum.b[i];
      if (!SolveCholesky(sum.a, neg_b, xi, &condition)) {
        result.failure = "singular normal equations";
        return result;
      }
      rel = Pose::FromTwist(xi) * rel;
      rel.Orthonormalize();
      double step2 = 0;
      for (double v : xi) step2 += v * v;
      // Converged on this level: |xi| < 3e-5 (0.03 mm, 0.002 deg), far below the depth noise.
      if (step2 < 1e-9) break;
    }
  }
  Association match;
  for (int i = 0; i < 9; ++i) match.r[i] = static_cast<float>(rel.r[i]);
  for (int i = 0; i < 3; ++i) match.t[i] = static_cast<float>(rel.t[i]);
  match.points = &model.points[0];
  match.normals = &model.normals[0];
  match.k = model.intrinsics[0];
  match.dmax2 = dmax2;
  match.cos_max = cos_max;
  FrameNormalEquations(frame.vertices[offset], frame.normals[offset], options.observability_block,
                       &match, result.matched_normal_equations, &result.matched_pairs,
                       &result.matched_mean_depth_m, pool);
  result.inlier_fraction = valid0 > 0 ? static_cast<float>(last.n) / valid0 : 0.0f;
  result.rms_m = last.n > 0 ? static_cast<float>(std::sqrt(last.r2 / last.n)) : 0.0f;
  const Pose estimate = model.camera_to_world * rel;
  const Pose motion = initial.Inverse() * estimate;
  const double moved =
      std::sqrt(motion.t[0] * motion.t[0] + motion.t[1] * motion.t[1] + motion.t[2] * motion.t[2]);
  const double turned = motion.RotationAngle() * 180.0 / 3.14159265358979;
  if (result.inlier_fraction < options.min_inlier_fraction) {
    result.failure = "too few correspondences (" + std::to_string(result.inlier_fraction) + " < " +
                     std::to_string(options.min_inlier_fraction) + ")";
  } else if (result.rms_m > options.max_rms_m) {
    result.failure = "residual too large (" + std::to_string(result.rms_m) + " m)";
  } else if (condition < options.min_condition) {
    result.failure = "ill-conditioned (" + std::to_string(condition) + ")";
  } else if (moved > options.max_translation_m || turned > options.max_rotation_deg) {
    result.failure =
        "implausible motion (" + std::to_string(moved) + " m, " + std::to_string(turned) + " deg)";
  } else {
    result.ok = true;
    result.camera_to_world = estimate;
  }
  return result;
}

}  // namespace probeless::recon
