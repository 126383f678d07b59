// Near-field point lamps (docs/light.md, "Near-field lamps"): a robust Levenberg-Marquardt fit of
// K point lamps, a uniform ambient term and per-chromaticity albedos to the grey image, the nested
// distant model on the same rows for model selection, and the SH light averaged over the visible
// surface points (the quantity SurfaceLightingTruth defines).
#include "probeless/light/point_light.h"

#include <time.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include "albedo_groups.h"
#include "probeless/linalg/cholesky.h"
#include "probeless/sh/sh.h"

namespace probeless::light {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kY0 = 0.28209479177387814;  // Y_0 = (A_0 / pi) Y_0: unoccluded T_0
constexpr int kMinRows = 32;
constexpr int kMinGroupRows = 16;
constexpr int kMaxParams = 9;
constexpr size_t kCoarseRows = 600;    // rows of the coarse searches (ranking only)
constexpr int kSearchDirections = 32;  // lamp search: Fibonacci directions from the centroid
// Median |residual| differences below this (image units, linear grey; a quarter of the smallest
// 8-bit sRGB step above black is ~8e-5, noise on rendered or sensor images is >= 1e-3) do not
// make a warm fit "worse" than the previous frame's.
constexpr double kWarmResidualFloor = 1e-3;

[[noreturn]] void Fail(const std::string& what) {
  throw LightError("light::EstimatePointLight: " + what);
}

// The fit's rows: back-projected point x and normal n (camera frame), grey intensity I, band-0
// transfer T_0 and albedo group.
struct Rows {
  std::vector<double> x, n, intensity, t0;
  std::vector<int> group;
  size_t size() const { return intensity.size(); }
};

// Shading of a lamp of unit intensity at p for albedo 1: max(0, n.(p - x)) / (pi |p - x|^3)
// (Lambert's cosine and the inverse square law, outgoing radiance = irradiance / pi) and its
// gradient with respect to p (grad may be null).
inline double LampShading(const double* x, const double* n, const double* p, double min_d2,
                          double* grad) {
  const double v[3] = {p[0] - x[0], p[1] - x[1], p[2] - x[2]};
  const double r2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
  const double d = n[0] * v[0] + n[1] * v[1] + n[2] * v[2];
  if (!(d > 0) || r2 < min_d2) {
    if (grad != nullptr) grad[0] = grad[1] = grad[2] = 0;
    return 0;
  }
  const double inv_r3 = 1.0 / (r2 * std::sqrt(r2));
  if (grad != nullptr) {
    const double k = 3 * d * inv_r3 / r2;
    for (int c = 0; c < 3; ++c) grad[c] = (n[c] * inv_r3 - k * v[c]) / kPi;
  }
  return d * inv_r3 / kPi;
}

// The model, albedo 1: point lamps, theta = [p_0, .., p_{K-1} (3 each), P_0 .. P_{K-1}, c], or the
// nested distant light, theta = [q (3: irradiance x direction), c]; c = band-0 SH coefficient of a
// uniform ambient light (radiance c Y_0, seen as c T_0).
struct Model {
  bool distant = false;
  int lamps = 1;
  double min_d2 = 0;
  int Size() const { return distant ? 4 : 4 * lamps + 1; }
  double Predict(const Rows& r, size_t i, const double* th, double* grad) const {
    const double* x = &r.x[3 * i];
    const double* n = &r.n[3 * i];
    const double t0 = r.t0[i];
    if (distant) {
      const double d = n[0] * th[0] + n[1] * th[1] + n[2] * th[2];
      const bool lit = d > 0;
      if (grad != nullptr) {
        for (int c = 0; c < 3; ++c) grad[c] = lit ? n[c] / kPi : 0;
        grad[3] = t0;
      }
      return (lit ? d / kPi : 0) + th[3] * t0;
    }
    double pred = 0;
    for (int k = 0; k < lamps; ++k) {
      const double power = th[3 * lamps + k];
      const double f =
          LampShading(x, n, &th[3 * k], min_d2, grad != nullptr ? &grad[3 * k] : nullptr);
      if (grad != nullptr) {
        for (int c = 0; c < 3; ++c) grad[3 * k + c] *= power;
        grad[3 * lamps + k] = f;
      }
      pred += power * f;
    }
    if (grad != nullptr) grad[4 * lamps] = t0;
    return pred + th[4 * lamps] * t0;
  }
  // Intensities and ambient are non-negative (projected after each step).
  void Project(double* th) const {
    if (!distant) {
      for (int k = 0; k < lamps; ++k) th[3 * lamps + k] = std::max(0.0, th[3 * lamps + k]);
    }
    th[Size() - 1] = std::max(0.0, th[Size() - 1]);
  }
};

// Rows, their albedo parameters and the robust weights of one fit: every row's albedo is a
// parameter a_g of its chromaticity group (groups with fewer than kMinGroupRows rows share one).
struct Albedos {
  std::vector<int> of_row;    // parameter index per row
  std::vector<double> value;  // per parameter
  double At(size_t i) const { return value[of_row[i]]; }
};

Albedos MakeAlbedos(const Rows& r, int groups, double albedo) {
  std::vector<int> count(groups, 0);
  for (int g : r.group) ++count[g];
  std::vector<int> index(groups, -1);
  int params = 0;
  for (int g = 0; g < groups; ++g) {
    if (count[g] >= kMinGroupRows) index[g] = params++;
  }
  bool shared = false;
  for (int g = 0; g < groups; ++g) {
    if (count[g] > 0 && index[g] < 0) shared = true;
  }
  Albedos a;
  a.value.assign(params + (shared ? 1 : 0), albedo);
  a.of_row.resize(r.size());
  for (size_t i = 0; i < r.size(); ++i) {
    const int g = index[r.group[i]];
    a.of_row[i] = g >= 0 ? g : params;
  }
  return a;
}

double Cost(const Model& m, const Rows& r, const Albedos& a, const std::vector<double>& w,
            const double* th) {
  double cost = 0;
  for (size_t i = 0; i < r.size(); ++i) {
    if (w[i] <= 0) continue;
    const double e = r.intensity[i] - a.At(i) * m.Predict(r, i, th, nullptr);
    cost += w[i] * e * e;
  }
  return cost;
}

// The light/albedo scale is free (a_g f = (s a_g)(f / s)): rescales the albedos to a row-mean of
// `albedo` and the light's linear parameters (intensities, ambient; q for the distant model)
// inversely.
void Normalise(const Model& m, const Rows& r, double albedo, Albedos* a, double* th) {
  double sum = 0;
  for (size_t i = 0; i < r.size(); ++i) sum += a->At(i);
  if (!(sum > 0)) return;
  const double s = albedo * static_cast<double>(r.size()) / sum;
  for (double& v : a->value) v *= s;
  if (m.distant) {
    for (int c = 0; c < 4; ++c) th[c] /= s;
  } else {
    for (int k = 3 * m.lamps; k < m.Size(); ++k) th[k] /= s;
  }
}

// Levenberg-Marquardt (Marquardt's diagonal scaling) on sum_i w_i (I_i - a_g(i) f_i(theta))^2
// over theta and the group albedos jointly, projected onto the bounds after each step (albedos
// > 0). Returns the final cost.
double Minimise(const Model& m, const Rows& r, Albedos* a, const std::vector<double>& w,
                int iterations, double* th) {
  const int nm = m.Size();
  const int na = static_cast<int>(a->value.size());
  const int n = nm + na;
  double cost = Cost(m, r, *a, w, th);
  double lambda = 1e-3;
  std::vector<double> jtj(n * n), jte(n), sys(n * n), step(n);
  double grad[kMaxParams], trial[kMaxParams];
  Albedos trial_a = *a;
  for (int it = 0; it < iterations; ++it) {
    std::fill(jtj.begin(), jtj.end(), 0.0);
    std::fill(jte.begin(), jte.end(), 0.0);
    for (size_t i = 0; i < r.size(); ++i) {
      if (w[i] <= 0) continue;
      const double f = m.Predict(r, i, th, grad);
      const int g = nm + a->of_row[i];
      const double ai = a->value[g - nm];
      const double e = r.intensity[i] - ai * f;
      for (int p = 0; p < nm; ++p) {
        const double jp = w[i] * ai * grad[p];
        jte[p] += jp * e;
        for (int q = 0; q <= p; ++q) jtj[p * n + q] += jp * ai * grad[q];
        jtj[g * n + p] += jp * f;  // row g > p: lower triangle
      }
      jte[g] += w[i] * f * e;
      jtj[g * n + g] += w[i] * f * f;
    }
    double max_diag = 0;
    for (int p = 0; p < n; ++p) max_diag = std::max(max_diag, jtj[p * n + p]);
    if (!(max_diag > 0)) break;
    bool accepted = false;
    for (int attempt = 0; attempt < 10 && !accepted; ++attempt) {
      sys = jtj;
      for (int p = 0; p < n; ++p) sys[p * n + p] += lambda * (jtj[p * n + p] + 1e-9 * max_diag);
      step = jte;
      if (!linalg::CholeskyFactor(sys.data(), n)) {
        lambda *= 10;
        continue;
      }
      linalg::CholeskySolveFactored(sys.data(), n, step.data());
      for (int p = 0; p < nm; ++p) trial[p] = th[p] + step[p];
      m.Project(trial);
      for (int g = 0; g < na; ++g) {
        trial_a.value[g] = std::max(1e-3 * a->value[g], a->value[g] + step[nm + g]);
      }
      const double c = Cost(m, r, trial_a, w, trial);
      if (c < cost) {
        const double gain = cost - c;
        std::copy_n(trial, nm, th);
        a->value = trial_a.value;
        cost = c;
        lambda = std::max(1e-9, lambda * 0.2);
        accepted = true;
        if (gain < 1e-6 * cost) return cost;
      } else {
        lambda *= 10;
      }
    }
    if (!accepted) break;
  }
  return cost;
}

std::vector<double> Residuals(const Model& m, const Rows& r, const Albedos& a, const double* th) {
  std::vector<double> e(r.size());
  for (size_t i = 0; i < r.size(); ++i) {
    e[i] = r.intensity[i] - a.At(i) * m.Predict(r, i, th, nullptr);
  }
  return e;
}

double MedianAbs(const std::vector<double>& e) {
  std::vector<double> v(e.size());
  for (size_t i = 0; i < e.size(); ++i) v[i] = std::abs(e[i]);
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

// IRLS weights from the residuals: Huber (k = 1.345) or Tukey's biweight (c = 4.685), MAD scale.
void RobustWeights(const std::vector<double>& e, bool tukey, std::vector<double>* w) {
  const double sigma = std::max(1e-6, 1.4826 * MedianAbs(e));
  for (size_t i = 0; i < e.size(); ++i) {
    const double u = std::abs(e[i]) / sigma;
    if (tukey) {
      const double t = u / 4.685;
      (*w)[i] = t < 1 ? (1 - t * t) * (1 - t * t) : 0;
    } else {
      (*w)[i] = u <= 1.345 ? 1 : 1.345 / u;
    }
  }
}

// The robust fit of one model (light and albedos jointly) from theta: a plain LM solve, then
// huber_iterations Huber and tukey_iterations Tukey reweightings, each followed by an LM solve.
// Returns the final weights in `w`.
void Fit(const Model& m, const Rows& r, const PointLightOptions& o, Albedos* a,
         std::vector<double>* w, double* th) {
  std::fill(w->begin(), w->end(), 1.0);
  Minimise(m, r, a, *w, o.lm_iterations, th);
  for (int k = 0; k < o.huber_iterations + o.tukey_iterations; ++k) {
    RobustWeights(Residuals(m, r, *a, th), k >= o.huber_iterations, w);
    Minimise(m, r, a, *w, o.lm_iterations, th);
  }
  Normalise(m, r, o.albedo, a, th);
}

// Closed-form non-negative least squares for the linear parameters (intensities, ambient) given
// the shading columns cols[j][i] (a_i already applied), weights w: small normal equations, with
// negative entries dropped and the rest re-solved. Returns the cost; `x` gets the solution.
double SolveLinear(const std::vector<std::vector<double>>& cols, const Rows& r,
                   const std::vector<double>& w, std::vector<double>* x) {
  const int n = static_cast<int>(cols.size());
  std::vector<bool> active(n, true);
  x->assign(n, 0.0);
  for (int round = 0; round < n; ++round) {
    std::vector<int> idx;
    for (int j = 0; j < n; ++j) {
      if (active[j]) idx.push_back(j);
    }
    const int k = static_cast<int>(idx.size());
    std::vector<double> ata(k * k, 0.0), atb(k, 0.0);
    for (size_t i = 0; i < r.size(); ++i) {
      if (w[i] <= 0) continue;
      for (int p = 0; p < k; ++p) {
        const double cp = w[i] * cols[idx[p]][i];
        atb[p] += cp * r.intensity[i];
        for (int q = 0; q <= p; ++q) ata[p * k + q] += cp * cols[idx[q]][i];
      }
    }
    double tr = 0;
    for (int p = 0; p < k; ++p) tr += ata[p * k + p];
    for (int p = 0; p < k; ++p) ata[p * k + p] += 1e-9 * tr + 1e-30;
    x->assign(n, 0.0);
    if (!linalg::CholeskyFactor(ata.data(), k)) break;
    linalg::CholeskySolveFactored(ata.data(), k, atb.data());
    bool negative = false;
    for (int p = 0; p < k; ++p) {
      (*x)[idx[p]] = atb[p];
      if (atb[p] < 0) negative = true;
    }
    if (!negative) break;
    for (int p = 0; p < k; ++p) {
      if (atb[p] < 0) active[idx[p]] = false;
    }
    for (int p = 0; p < k; ++p) (*x)[idx[p]] = std::max(0.0, (*x)[idx[p]]);
  }
  double cost = 0;
  for (size_t i = 0; i < r.size(); ++i) {
    double pred = 0;
    for (int j = 0; j < n; ++j) pred += (*x)[j] * cols[j][i];
    const double e = r.intensity[i] - pred;
    cost += w[i] * e * e;
  }
  return cost;
}

// SolveLinear for two columns f (the candidate's) and c (fixed across candidates) from their
// weighted sums, in closed form (the same regularisation and active-set rule): the coarse
// searches rank hundreds of candidates, and one pass over the rows per candidate is what they
// cost. `sums` = {f.f, f.c, f.I}, `fixed` = {c.c, c.I, I.I} (all weighted). Returns the cost.
double SolveTwoColumns(const double* sums, const double* fixed, double* x0, double* x1) {
  const double ff = sums[0], fc = sums[1], fi = sums[2];
  const double cc = fixed[0], ci = fixed[1], ii = fixed[2];
  const double tr = ff + cc;
  const double a = ff + 1e-9 * tr + 1e-30, d = cc + 1e-9 * tr + 1e-30;
  const double det = a * d - fc * fc;
  double p = 0, q = 0;
  if (det > 0) {
    p = (d * fi - fc * ci) / det;
    q = (a * ci - fc * fi) / det;
  }
  if (det > 0 && (p < 0 || q < 0)) {
    if (p < 0 && q < 0) {
      p = q = 0;
    } else if (p < 0) {
      p = 0;
      q = std::max(0.0, ci / (cc + 1e-9 * cc + 1e-30));
    } else {
      q = 0;
      p = std::max(0.0, fi / (ff + 1e-9 * ff + 1e-30));
    }
  }
  *x0 = p, *x1 = q;
  return ii - 2 * (p * fi + q * ci) + p * p * ff + 2 * p * q * fc + q * q * cc;
}

// Every step-th row (with its albedo parameter and weight): the coarse searches only rank
// candidates, a few hundred rows do.
struct Subset {
  Rows rows;
  Albedos albedos;
  std::vector<double> w;
};

Subset Subsample(const Rows& r, const Albedos& a, const std::vector<double>& w, size_t step) {
  Subset s;
  s.albedos.value = a.value;
  for (size_t i = 0; i < r.size(); i += step) {
    s.rows.x.insert(s.rows.x.end(), &r.x[3 * i], &r.x[3 * i] + 3);
    s.rows.n.insert(s.rows.n.end(), &r.n[3 * i], &r.n[3 * i] + 3);
    s.rows.intensity.push_back(r.intensity[i]);
    s.rows.t0.push_back(r.t0[i]);
    s.rows.group.push_back(r.group[i]);
    s.albedos.of_row.push_back(a.of_row[i]);
    s.w.push_back(w[i]);
  }
  return s;
}

struct Candidate {
  double cost = 0;
  double p[3] = {0, 0, 0};
  std::vector<double> linear;
};

// Coarse search for one more lamp (positions around the surface centroid along kSearchDirections
// Fibonacci directions and the initial direction, at 5 distances, 0.5 to 4 m), the lamps in `fixed`
// kept where they are; each candidate's intensities and ambient by SolveLinear. Returns the best
// `keep` candidates at least 0.3 m apart, cheapest first.
std::vector<Candidate> SearchLamp(const Rows& r, const Albedos& a, const std::vector<double>& w,
                                  const std::vector<double>& fixed, const Vec3f* initial_direction,
                                  double min_d2, int keep) {
  double centroid[3] = {0, 0, 0};
  for (size_t i = 0; i < r.size(); ++i) {
    for (int c = 0; c < 3; ++c) centroid[c] += r.x[3 * i + c];
  }
  for (double& c : centroid) c /= static_cast<double>(r.size());
  std::vector<sh::Vec3> dirs = sh::FibonacciSphere(kSearchDirections);
  if (initial_direction != nullptr) {
    const Vec3f& d = *initial_direction;
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (len > 0) dirs.push_back({d[0] / len, d[1] / len, d[2] / len});
  }
  const double distances[] = {0.5, 1.0, 1.7, 2.6, 4.0};
  const int fixed_lamps = static_cast<int>(fixed.size() / 3);
  std::vector<std::vector<double>> cols(fixed_lamps + 2, std::vector<double>(r.size()));
  for (int k = 0; k < fixed_lamps; ++k) {
    for (size_t i = 0; i < r.size(); ++i) {
      cols[k][i] = a.At(i) * LampShading(&r.x[3 * i], &r.n[3 * i], &fixed[3 * k], min_d2, nullptr);
    }
  }
  for (size_t i = 0; i < r.size(); ++i) cols[fixed_lamps + 1][i] = a.At(i) * r.t0[i];
  // One lamp and the ambient term: closed form from one pass per candidate.
  double fixed_sums[3] = {0, 0, 0};
  if (fixed_lamps == 0) {
    for (size_t i = 0; i < r.size(); ++i) {
      const double c = cols[1][i], y = r.intensity[i];
      fixed_sums[0] += w[i] * c * c, fixed_sums[1] += w[i] * c * y, fixed_sums[2] += w[i] * y * y;
    }
  }
  std::vector<Candidate> all;
  for (const sh::Vec3& d : dirs) {
    for (double dist : distances) {
      Candidate c;
      for (int k = 0; k < 3; ++k) c.p[k] = centroid[k] + dist * d[k];
      if (fixed_lamps == 0) {
        double sums[3] = {0, 0, 0};
        for (size_t i = 0; i < r.size(); ++i) {
          const double f = a.At(i) * LampShading(&r.x[3 * i], &r.n[3 * i], c.p, min_d2, nullptr);
          const double wf = w[i] * f;
          sums[0] += wf * f, sums[1] += wf * cols[1][i], sums[2] += wf * r.intensity[i];
        }
        c.linear.resize(2);
        c.cost = SolveTwoColumns(sums, fixed_sums, &c.linear[0], &c.linear[1]);
      } else {
        for (size_t i = 0; i < r.size(); ++i) {
          cols[fixed_lamps][i] =
              a.At(i) * LampShading(&r.x[3 * i], &r.n[3 * i], c.p, min_d2, nullptr);
        }
        c.cost = SolveLinear(cols, r, w, &c.linear);
      }
      all.push_back(std::move(c));
    }
  }
  std::sort(all.begin(), all.end(),
            [](const Candidate& x, const Candidate& y) { return x.cost < y.cost; });
  std::vector<Candidate> best;
  for (const Candidate& c : all) {
    bool distinct = true;
    for (const Candidate& b : best) {
      const double dx = c.p[0] - b.p[0], dy = c.p[1] - b.p[1], dz = c.p[2] - b.p[2];
      if (dx * dx + dy * dy + dz * dz < 0.09) distinct = false;
    }
    if (distinct) best.push_back(c);
    if (static_cast<int>(best.size()) >= keep) break;
  }
  return best;
}

// Every step-th row (the screen's rows).
Rows EveryNth(const Rows& r, size_t step) {
  Rows s;
  for (size_t i = 0; i < r.size(); i += step) {
    s.x.insert(s.x.end(), &r.x[3 * i], &r.x[3 * i] + 3);
    s.n.insert(s.n.end(), &r.n[3 * i], &r.n[3 * i] + 3);
    s.intensity.push_back(r.intensity[i]);
    s.t0.push_back(r.t0[i]);
    s.group.push_back(r.group[i]);
  }
  return s;
}

// Cold start of the one-lamp model: the coarse search on <= kCoarseRows rows, a short plain LM
// (o.lm_iterations) from the 3 best starts; theta of the cheapest (empty if none).
std::vector<double> ColdStart(const Model& point, const Rows& r, const Albedos& a0,
                              const PointLightOptions& o, const Vec3f* initial_direction,
                              double min_d2) {
  std::vector<double> ones(r.size(), 1.0);
  const size_t coarse_step = std::max<size_t>(1, r.size() / kCoarseRows);
  double best = INFINITY;
  std::vector<double> th;
  const Subset sub = Subsample(r, a0, ones, coarse_step);
  for (const Candidate& c :
       SearchLamp(sub.rows, sub.albedos, sub.w, {}, initial_direction, min_d2, 3)) {
    std::vector<double> t = {c.p[0], c.p[1], c.p[2], c.linear[0], c.linear[1]};
    Albedos a = a0;
    const double cost = Minimise(point, r, &a, ones, o.lm_iterations, t.data());
    if (cost < best) best = cost, th = t;
  }
  return th;
}

// The nested distant model (I = a_g (max(0, n.q) / pi + c T_0)) fitted to the rows like the point
// model (coarse search over 64 Fibonacci directions and the initial direction, then the robust
// fit); returns its median absolute residual.
double DistantMedianResidual(const Rows& r, const PointLightOptions& o, int groups,
                             const Vec3f* initial_direction, double min_d2) {
  Model distant{true, 0, min_d2};
  Albedos a = MakeAlbedos(r, groups, o.albedo);
  std::vector<double> w(r.size(), 1.0), ones(r.size(), 1.0);
  std::vector<sh::Vec3> dirs = sh::FibonacciSphere(64);
  if (initial_direction != nullptr) {
    const Vec3f& d = *initial_direction;
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (len > 0) dirs.push_back({d[0] / len, d[1] / len, d[2] / len});
  }
  const size_t coarse_step = std::max<size_t>(1, r.size() / kCoarseRows);
  const Subset sub = Subsample(r, a, ones, coarse_step);
  const Rows& rs = sub.rows;
  std::vector<double> ambient(rs.size());
  double fixed_sums[3] = {0, 0, 0};
  for (size_t i = 0; i < rs.size(); ++i) {
    ambient[i] = sub.albedos.At(i) * rs.t0[i];
    const double y = rs.intensity[i];
    fixed_sums[0] += sub.w[i] * ambient[i] * ambient[i];
    fixed_sums[1] += sub.w[i] * ambient[i] * y;
    fixed_sums[2] += sub.w[i] * y * y;
  }
  double best = INFINITY;
  std::vector<double> td;
  for (const sh::Vec3& d : dirs) {
    double sums[3] = {0, 0, 0};
    for (size_t i = 0; i < rs.size(); ++i) {
      const double c = rs.n[3 * i] * d[0] + rs.n[3 * i + 1] * d[1] + rs.n[3 * i + 2] * d[2];
      const double f = sub.albedos.At(i) * std::max(0.0, c) / kPi;
      const double wf = sub.w[i] * f;
      sums[0] += wf * f, sums[1] += wf * ambient[i], sums[2] += wf * rs.intensity[i];
    }
    double x0 = 0, x1 = 0;
    const double cost = SolveTwoColumns(sums, fixed_sums, &x0, &x1);
    if (cost < best) best = cost, td = {d[0] * x0, d[1] * x0, d[2] * x0, x1};
  }
  if (td.empty()) td = {0, 0, 0, 0};
  if (td[0] == 0 && td[1] == 0 && td[2] == 0) td[1] = -1e-3;  // a start off the kink
  Fit(distant, r, o, &a, &w, td.data());
  return MedianAbs(Residuals(distant, r, a, td.data()));
}

// p90 angle (degrees) between the direction to a lamp at p from each point (3 values per point)
// and the unit direction d / scale (d given unnormalised with its length as scale, as the callers
// have it); -1 when no point differs from p.
double SpreadAroundDeg(const double* p, const std::vector<double>& points, const double d[3],
                       double scale) {
  const size_t np = points.size() / 3;
  std::vector<double> angles;
  for (size_t i = 0; i < np; ++i) {
    const double* x = &points[3 * i];
    const double v[3] = {p[0] - x[0], p[1] - x[1], p[2] - x[2]};
    const double len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (!(len > 0)) continue;
    double dot = 0;
    for (int c = 0; c < 3; ++c) dot += v[c] / len * d[c] / scale;
    angles.push_back(std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / kPi);
  }
  if (angles.empty()) return -1;
  const size_t q = std::min(angles.size() - 1, angles.size() * 9 / 10);
  std::nth_element(angles.begin(), angles.begin() + q, angles.end());
  return angles[q];
}

// SpreadAroundDeg around the irradiance-weighted (1 / r^2) mean of those directions: the auto
// rule's spread (0 without any direction).
double LampSpreadDeg(const double* p, const std::vector<double>& points, double min_d2) {
  const size_t np = points.size() / 3;
  double mean[3] = {0, 0, 0};
  for (size_t i = 0; i < np; ++i) {
    const double* x = &points[3 * i];
    const double v[3] = {p[0] - x[0], p[1] - x[1], p[2] - x[2]};
    const double len2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    const double len = std::sqrt(len2);
    if (!(len > 0)) continue;
    const double e = 1.0 / std::max(min_d2, len2);
    for (int c = 0; c < 3; ++c) mean[c] += e * v[c] / len;
  }
  const double ml = std::sqrt(mean[0] * mean[0] + mean[1] * mean[1] + mean[2] * mean[2]);
  if (!(ml > 0)) return 0;
  return std::max(0.0, SpreadAroundDeg(p, points, mean, ml));
}

}  // namespace

LightModel ParseLightModel(std::string_view name) {
  if (name == "distant") return LightModel::kDistant;
  if (name == "point") return LightModel::kPoint;
  if (name == "auto") return LightModel::kAuto;
  throw LightError("light::ParseLightModel: light model must be distant, point or auto, got '" +
                   std::string(name) + "'");
}

const char* LightModelName(LightModel model) {
  switch (model) {
    case LightModel::kDistant:
      return "distant";
    case LightModel::kPoint:
      return "point";
    case LightModel::kAuto:
      return "auto";
  }
  return "?";
}

PointLightEstimate EstimatePointLight(const GeometryView& g, std::span<const float> intensity,
                                      const PointLightOptions& o, int bands,
                                      const TransferResult* transfer,
                                      std::span<const uint8_t> colour,
                                      const Vec3f* initial_direction, PointLightTracker* tracker) {
  ValidateGeometryView(g, "EstimatePointLight");
  const size_t pixels = static_cast<size_t>(g.width) * g.height;
  if (intensity.size() != pixels) {
    Fail("intensity has " + std::to_string(intensity.size()) + " values, expected " +
         std::to_string(g.width) + "x" + std::to_string(g.height));
  }
  if (!colour.empty() && colour.size() != 3 * pixels) {
    Fail("colour has " + std::to_string(colour.size()) + " bytes, expected 3x" +
         std::to_string(g.width) + "x" + std::to_string(g.height));
  }
  if (transfer != nullptr && (transfer->width != g.width || transfer->height != g.height ||
                              transfer->coefficient_count < 1 ||
                              transfer->transfer.size() != pixels * transfer->coefficient_count ||
                              transfer->valid.size() != pixels)) {
    Fail("transfer is " + std::to_string(transfer->width) + "x" + std::to_string(transfer->height) +
         ", expected " + std::to_string(g.width) + "x" + std::to_string(g.height));
  }
  if (o.max_lamps < 1 || o.max_lamps > 2) Fail("max_lamps must be 1 or 2");
  if (o.max_rows < kMinRows) Fail("max_rows must be >= " + std::to_string(kMinRows));
  if (!(o.albedo > 0)) Fail("albedo must be > 0");
  if (o.lm_iterations < 1 || o.huber_iterations < 0 || o.tukey_iterations < 0 ||
      o.albedo_groups < 0) {
    Fail("iteration and group counts must be >= 0 (lm_iterations >= 1)");
  }
  if (bands < 1 || bands > 5) Fail("bands must be 1..5, got " + std::to_string(bands));
  if (o.surface_stride < 1) Fail("surface_stride must be >= 1");
  if (o.screen_rows < 0 || o.warm_lm_iterations < 1 || o.screen_lm_iterations < 1) {
    Fail("screen_rows must be >= 0, warm_lm_iterations and screen_lm_iterations >= 1");
  }
  if (o.albedo_groups > 255)
    Fail("albedo_groups must be 0..255, got " + std::to_string(o.albedo_groups));
  if (!(o.min_intensity >= 0) || !(o.max_intensity > o.min_intensity)) {
    Fail("min_intensity must be >= 0 and below max_intensity");
  }
  if (!(o.min_lamp_distance_m > 0) || !std::isfinite(o.min_lamp_distance_m)) {
    Fail("min_lamp_distance_m must be finite and > 0");
  }
  for (const float v : {o.second_lamp_gain, o.auto_min_gain, o.auto_min_spread_deg,
                        o.screen_min_gain, o.screen_min_spread_deg}) {
    if (!std::isfinite(v)) Fail("gains and spreads must be finite");
  }
  if (!(o.warm_max_residual_ratio >= 1)) Fail("warm_max_residual_ratio must be >= 1");
  // Every return below without a used point fit leaves the tracker reset.
  const bool warm = tracker != nullptr && tracker->Active();
  PointLightTracker previous;
  if (tracker != nullptr) {
    previous = *tracker;
    tracker->Reset();
  }

  const auto& k = g.intrinsics;
  auto has_surface = [&](size_t p) {
    const float z = g.depth[p];
    const float* n = &g.normals[3 * p];
    return z > 0 && std::isfinite(z) && (n[0] != 0 || n[1] != 0 || n[2] != 0) &&
           std::isfinite(n[0] + n[1] + n[2]);
  };
  auto usable = [&](size_t p) {
    const float i = intensity[p];
    return has_surface(p) && i >= o.min_intensity && i <= o.max_intensity;
  };
  // The usable pixels (for the row stride) counted on every 4th row and column, x 16: a full pass
  // costs ~1.2 ms at 640x480, as much as the rest of a screened-out frame.
  size_t surface = 0, count = 0;
  for (int v = 0; v < g.height; v += 4) {
    for (int u = 0; u < g.width; u += 4) {
      const size_t p = static_cast<size_t>(v) * g.width + u;
      if (!has_surface(p)) continue;
      ++surface;
      const float i = intensity[p];
      if (i >= o.min_intensity && i <= o.max_intensity) ++count;
    }
  }
  count *= 16;
  for (size_t p = 0; surface == 0 && p < pixels; ++p) {
    if (has_surface(p)) surface = 1;
  }
  if (surface == 0) Fail("no valid pixels (depth > 0 with a normal)");
  PointLightEstimate out;
  const int stride =
      std::max(2, static_cast<int>(std::ceil(std::sqrt(static_cast<double>(count) / o.max_rows))));
  const bool grouped = !colour.empty() && o.albedo_groups > 0;
  const int cells = grouped ? o.albedo_groups : 1;
  Rows r;
  std::vector<float> row_rgb;  // linear colour per row (grouped)
  for (int v = stride / 2; v < g.height; v += stride) {
    for (int u = stride / 2; u < g.width; u += stride) {
      const size_t p = static_cast<size_t>(v) * g.width + u;
      if (!usable(p)) continue;
      if (grouped) {
        const float cr = SrgbToLinear(colour[3 * p]), cg = SrgbToLinear(colour[3 * p + 1]),
                    cb = SrgbToLinear(colour[3 * p + 2]);
        if (!(cr + cg + cb > 0)) continue;
        row_rgb.insert(row_rgb.end(), {cr, cg, cb});
      }
      const double z = g.depth[p];
      r.x.insert(r.x.end(), {(u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z});
      const float* n = &g.normals[3 * p];
      const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      r.n.insert(r.n.end(), {n[0] / len, n[1] / len, n[2] / len});
      r.intensity.push_back(intensity[p]);
      double t0 = kY0;
      if (transfer != nullptr && transfer->valid[p]) {
        t0 = transfer->transfer[p * transfer->coefficient_count];
      }
      r.t0.push_back(t0);
    }
  }
  int groups = 1;
  if (grouped) {
    r.group = internal::AlbedoGroupIds(row_rgb, cells, o.albedo_invariant, &groups);
  } else {
    r.group.assign(r.size(), 0);
  }
  out.rows = static_cast<int>(r.size());
  if (r.size() < static_cast<size_t>(kMinRows)) return out;

  const double min_d2 = static_cast<double>(o.min_lamp_distance_m) * o.min_lamp_distance_m;
  std::vector<double> ones(r.size(), 1.0);
  const size_t coarse_step = std::max<size_t>(1, r.size() / kCoarseRows);
  Model point{false, 1, min_d2};
  // Screen (cold starts with selection only): the selection on a subset of the rows; a clear
  // "distant" there ends the estimate. The full rule runs after a passed screen, so the screen
  // can only turn "point" into "distant", never the reverse.
  if (o.select_model && !warm && o.screen_rows > 0 &&
      r.size() >= 2 * static_cast<size_t>(o.screen_rows)) {
    const Rows rs = EveryNth(r, r.size() / o.screen_rows);
    PointLightOptions so = o;
    so.huber_iterations = std::min(o.huber_iterations, 1);
    so.tukey_iterations = std::min(o.tukey_iterations, 1);
    so.lm_iterations = o.screen_lm_iterations;
    Albedos a = MakeAlbedos(rs, groups, o.albedo);
    std::vector<double> w(rs.size(), 1.0);
    std::vector<double> t = ColdStart(point, rs, a, so, initial_direction, min_d2);
    if (!t.empty()) {
      Fit(point, rs, so, &a, &w, t.data());
      const double med_point = MedianAbs(Residuals(point, rs, a, t.data()));
      const double med_distant = DistantMedianResidual(rs, so, groups, initial_direction, min_d2);
      const double gain = med_distant > 0 ? 1 - med_point / med_distant : 0;
      const double spread = LampSpreadDeg(t.data(), rs.x, min_d2);
      out.screen_gain = static_cast<float>(gain);
      out.screen_spread_deg = static_cast<float>(spread);
      if (gain < o.screen_min_gain || spread < o.screen_min_spread_deg) {
        out.screened_out = true;
        out.median_residual_point = med_point;
        out.median_residual_distant = med_distant;
        out.spread_deg = static_cast<float>(spread);
        return out;
      }
    }
  }
  // One lamp: warm start from the tracker's strongest lamp, or the cold search (a short plain LM
  // from the 3 best starts); then the robust fit.
  Albedos a_point = MakeAlbedos(r, groups, o.albedo);
  std::vector<double> w_point(r.size(), 1.0);
  std::vector<double> th;
  if (warm) {
    PointLightOptions wo = o;
    wo.lm_iterations = o.warm_lm_iterations;
    th = {previous.position[0], previous.position[1], previous.position[2], previous.intensity[0],
          previous.ambient};
    Fit(point, r, wo, &a_point, &w_point, th.data());
    out.median_residual_point = MedianAbs(Residuals(point, r, a_point, th.data()));
    out.warm_started = true;
    if (!(out.median_residual_point <=
          o.warm_max_residual_ratio * previous.median_residual + kWarmResidualFloor)) {
      // The lamp moved too far, switched, or the scene changed: the cold fit as well, the
      // better one is kept.
      Albedos a_cold = MakeAlbedos(r, groups, o.albedo);
      std::vector<double> w_cold(r.size(), 1.0);
      std::vector<double> t_cold = ColdStart(point, r, a_cold, o, initial_direction, min_d2);
      if (!t_cold.empty()) {
        Fit(point, r, o, &a_cold, &w_cold, t_cold.data());
        const double med = MedianAbs(Residuals(point, r, a_cold, t_cold.data()));
        if (med < out.median_residual_point) {
          th = t_cold, a_point = a_cold, w_point = w_cold;
          out.median_residual_point = med;
          out.warm_started = false;
        }
      }
    }
  } else {
    th = ColdStart(point, r, a_point, o, initial_direction, min_d2);
    if (th.empty()) return out;  // no finite start (cannot happen with finite, filtered rows)
    Fit(point, r, o, &a_point, &w_point, th.data());
    out.median_residual_point = MedianAbs(Residuals(point, r, a_point, th.data()));
  }
  // Optional second lamp: searched with the first one fixed, then both refined together.
  if (o.max_lamps >= 2) {
    const std::vector<double> first(th.begin(), th.begin() + 3);
    const Subset sub = Subsample(r, a_point, ones, coarse_step);
    const auto c2 = SearchLamp(sub.rows, sub.albedos, sub.w, first, nullptr, min_d2, 1);
    if (!c2.empty()) {
      Model two{false, 2, min_d2};
      std::vector<double> t2 = {th[0],           th[1],           th[2],
                                c2[0].p[0],      c2[0].p[1],      c2[0].p[2],
                                c2[0].linear[0], c2[0].linear[1], c2[0].linear[2]};
      Albedos a2 = a_point;
      std::vector<double> w2 = w_point;
      Fit(two, r, o, &a2, &w2, t2.data());
      const double med2 = MedianAbs(Residuals(two, r, a2, t2.data()));
      if (med2 < (1 - o.second_lamp_gain) * out.median_residual_point && t2[6] > 0 && t2[7] > 0) {
        point = two;
        th = t2;
        a_point = a2;
        w_point = w2;
        out.median_residual_point = med2;
      }
    }
  }
  // The nested distant model on the same rows, for the model selection.
  if (o.select_model) {
    // A warm stream (the point model was used in the previous frame) needs the gain only to
    // notice that the scene turned distant: the shorter solves of the warm fit do.
    PointLightOptions dopt = o;
    if (warm) dopt.lm_iterations = o.warm_lm_iterations;
    out.median_residual_distant = DistantMedianResidual(r, dopt, groups, initial_direction, min_d2);
  }

  // Outputs at the visible surface points (as SurfaceLightingTruth).
  const int lamps = point.lamps;
  std::vector<double> points;
  for (int v = o.surface_stride / 2; v < g.height; v += o.surface_stride) {
    for (int u = o.surface_stride / 2; u < g.width; u += o.surface_stride) {
      const double z = g.depth[static_cast<size_t>(v) * g.width + u];
      if (!(z > 0) || !std::isfinite(z)) continue;
      points.insert(points.end(), {(u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z});
    }
  }
  const size_t np = points.size() / 3;
  const int cc = bands * bands;
  struct LampSums {
    double irradiance = 0;
    double direction[3] = {0, 0, 0};
    std::vector<double> sh;
  };
  std::vector<LampSums> sums(lamps);
  std::vector<double> y(cc);
  for (int l = 0; l < lamps; ++l) {
    sums[l].sh.assign(cc, 0.0);
    const double* p = &th[3 * l];
    const double power = th[3 * lamps + l];
    for (size_t i = 0; i < np; ++i) {
      const double* x = &points[3 * i];
      const double v[3] = {p[0] - x[0], p[1] - x[1], p[2] - x[2]};
      const double r2 = std::max(min_d2, v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
      const double len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
      if (!(len > 0)) continue;
      const double e = power / r2;
      sh::EvaluateBasis<double>(bands, v[0] / len, v[1] / len, v[2] / len, y.data());
      for (int c = 0; c < cc; ++c) sums[l].sh[c] += e * y[c];
      sums[l].irradiance += e;
      for (int c = 0; c < 3; ++c) sums[l].direction[c] += e * v[c] / len;
    }
  }
  std::vector<int> order(lamps);
  for (int l = 0; l < lamps; ++l) order[l] = l;
  std::sort(order.begin(), order.end(),
            [&](int x, int z) { return sums[x].irradiance > sums[z].irradiance; });
  LightEstimate& e = out.light;
  e.bands = bands;
  e.coefficients.assign(cc, 0.0);
  const double inv = np > 0 ? 1.0 / static_cast<double>(np) : 0.0;
  for (int l : order) {
    out.lamps.push_back({{static_cast<float>(th[3 * l]), static_cast<float>(th[3 * l + 1]),
                          static_cast<float>(th[3 * l + 2])},
                         static_cast<float>(th[3 * lamps + l])});
    for (int c = 0; c < cc; ++c) e.coefficients[c] += sums[l].sh[c] * inv;
  }
  out.ambient = static_cast<float>(th[4 * lamps]);
  e.coefficients[0] += th[4 * lamps];
  const LampSums& top = sums[order[0]];
  const double dl =
      std::sqrt(top.direction[0] * top.direction[0] + top.direction[1] * top.direction[1] +
                top.direction[2] * top.direction[2]);
  if (dl > 0) {
    for (int c = 0; c < 3; ++c) e.dominant_direction[c] = static_cast<float>(top.direction[c] / dl);
    e.intensity = static_cast<float>(top.irradiance * inv);
    // Spread: p90 angle between the lamp's direction at a point and the mean direction.
    const double d[3] = {e.dominant_direction[0], e.dominant_direction[1], e.dominant_direction[2]};
    const double spread = SpreadAroundDeg(&th[3 * order[0]], points, d, 1.0);
    if (spread >= 0) out.spread_deg = static_cast<float>(spread);
  }
  // Fit quality: weighted R^2 in image units.
  const std::vector<double> res = Residuals(point, r, a_point, th.data());
  double sw = 0, swi = 0;
  for (size_t i = 0; i < r.size(); ++i) sw += w_point[i], swi += w_point[i] * r.intensity[i];
  const double mean = sw > 0 ? swi / sw : 0;
  double swr2 = 0, swt2 = 0;
  for (size_t i = 0; i < r.size(); ++i) {
    swr2 += w_point[i] * res[i] * res[i];
    swt2 += w_point[i] * (r.intensity[i] - mean) * (r.intensity[i] - mean);
  }
  const double r2 = swt2 > 0 ? std::clamp(1.0 - swr2 / swt2, 0.0, 1.0) : 0.0;
  e.confidence = static_cast<float>(r2 * std::min(1.0, sw / (20.0 * cc)));
  e.rms_residual = sw > 0 ? std::sqrt(swr2 / sw) : 0;
  e.pixels = out.rows;
  e.valid = dl > 0;
  out.valid = e.valid;
  const double gain = out.median_residual_distant > 0
                          ? 1 - out.median_residual_point / out.median_residual_distant
                          : 0;
  out.prefers_point = o.select_model && out.valid && gain >= o.auto_min_gain &&
                      out.spread_deg >= o.auto_min_spread_deg;
  if (tracker != nullptr && out.valid && (!o.select_model || out.prefers_point)) {
    for (const PointLamp& l : out.lamps) {
      tracker->position.insert(tracker->position.end(),
                               {l.position[0], l.position[1], l.position[2]});
      tracker->intensity.push_back(l.intensity);
    }
    tracker->ambient = out.ambient;
    tracker->median_residual = out.median_residual_point;
  }
  return out;
}

namespace {

// CPU time of the calling thread (ms): the point fit runs on it alone.
double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

}  // namespace

SceneLightResult EstimateSceneLight(const GeometryView& g, const TransferResult& transfer,
                                    std::span<const float> intensity,
                                    const SceneLightOptions& options,
                                    std::span<const uint8_t> colour, PointLightTracker* tracker,
                                    std::span<const float> distant_weights) {
  SceneLightResult out;
  out.distant = EstimateLight(transfer, intensity, options.distant, colour, distant_weights);
  out.light = out.distant;
  out.used = LightModel::kDistant;
  // Cast shadows refine the distant light only (parallel shadow rays); `distant` stays the fit's.
  auto shadows = [&] {
    if (options.shadow.enabled && out.used == LightModel::kDistant && out.light.valid) {
      out.shadow = RefineLightWithShadows(g, intensity, options.shadow, colour, &out.light);
    }
  };
  if (options.model == LightModel::kDistant || !out.distant.valid) {
    if (tracker != nullptr) tracker->Reset();
    shadows();
    return out;
  }
  const int bands = options.distant.bands > 0
                        ? options.distant.bands
                        : static_cast<int>(std::lround(std::sqrt(transfer.coefficient_count)));
  const bool has_direction = out.distant.dominant_direction[0] != 0 ||
                             out.distant.dominant_direction[1] != 0 ||
                             out.distant.dominant_direction[2] != 0;
  PointLightOptions po = options.point;
  po.select_model = options.model == LightModel::kAuto;
  const double cpu0 = ThreadCpuMs();
  out.point =
      EstimatePointLight(g, intensity, po, bands, &transfer, colour,
                         has_direction ? &out.distant.dominant_direction : nullptr, tracker);
  auto usable = [&] {
    return options.model == LightModel::kPoint ? out.point.valid : out.point.prefers_point;
  };
  if (out.point.warm_started && !usable()) {
    // The lamp moved or went off: a fit from the old lamp can settle where the model rule rejects
    // it although a cold fit of this frame would not (and the next frame, cold again, would
    // flip back), so the frame gets the cold fit a fresh stream would make.
    tracker->Reset();
    out.point =
        EstimatePointLight(g, intensity, po, bands, &transfer, colour,
                           has_direction ? &out.distant.dominant_direction : nullptr, tracker);
  }
  out.point_thread_cpu_ms = ThreadCpuMs() - cpu0;
  const bool use = usable();
  if (use) {
    out.light = out.point.light;
    out.used = LightModel::kPoint;
  }
  shadows();
  return out;
}

}  // namespace probeless::light
