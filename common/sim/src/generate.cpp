#include "probeless/sim/generate.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <set>
#include <sstream>

#include "denoise.h"
#include "probeless/raytrace/pathtrace.h"
#include "probeless/raytrace/render.h"
#include "probeless/sh/sh.h"
#include "sensor.h"

namespace probeless::sim {
namespace {

using internal::Rng;
using internal::SplitMix64;
using raytrace::Mat3;
using raytrace::Transform;
using raytrace::Vec3;

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180;
constexpr double kFps = 30;
constexpr float kWall = 0.1f;  // wall, floor and ceiling thickness, metres

Transform At(Vec3 p, double yaw_rad = 0) {
  Transform t;
  t.rotation = Mat3::AxisAngle({0, 1, 0}, yaw_rad);
  t.translation = {p.x, p.y, p.z};
  return t;
}

// Luminance weights of linear Rec. 709 RGB.
float Luminance(Vec3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

// A saturated colour of hue h in [0, 1) and saturation s (value 1), linear RGB.
Vec3 Hue(double h, double s) {
  const double k[3] = {5, 3, 1};
  Vec3 out;
  for (int c = 0; c < 3; ++c) {
    const double kk = std::fmod(k[c] + h * 6, 6.0);
    const double v = 1 - s * std::max(0.0, std::min({kk, 4 - kk, 1.0}));
    out[c] = static_cast<float>(v);
  }
  return out;
}

Vec3 RandomAlbedo(Rng& rng, double lo, double hi, double saturation) {
  const Vec3 hue = Hue(rng.Uniform(), saturation * rng.Uniform());
  const float level = static_cast<float>(rng.Uniform(lo, hi));
  return hue * level;
}

// An optional procedural pattern on a surface material (floors, walls, furniture).
void MaybePattern(Rng& rng, double probability, raytrace::Material& m) {
  if (rng.Uniform() >= probability) return;
  const double pick = rng.Uniform();
  m.pattern.kind = pick < 0.35  ? raytrace::ProceduralPattern::Kind::kChecker
                   : pick < 0.7 ? raytrace::ProceduralPattern::Kind::kValueNoise
                                : raytrace::ProceduralPattern::Kind::kStripes;
  m.pattern.color_b = m.albedo * static_cast<float>(rng.Uniform(0.35, 0.8));
  m.pattern.period_m = static_cast<float>(rng.Uniform(0.05, 0.5));
  m.pattern.axis = rng.Uniform() < 0.5 ? Vec3{1, 0, 0} : Vec3{0, 0, 1};
}

void MaybeGloss(Rng& rng, double probability, raytrace::Material& m) {
  if (rng.Uniform() >= probability) return;
  m.specular_f0 = static_cast<float>(rng.Uniform(0.02, 0.06));
  m.roughness = static_cast<float>(rng.Uniform(0.25, 0.8));
}

GeneratedObject Box(const std::string& name, Vec3 size, Vec3 centre, raytrace::Material m,
                    double yaw = 0) {
  GeneratedObject o;
  o.name = name;
  o.shape = "box";
  o.size = size;
  o.object_to_world = At(centre, yaw);
  o.material = std::move(m);
  return o;
}

// An axis-aligned slab [lo, hi] as a box object.
GeneratedObject Slab(const std::string& name, Vec3 lo, Vec3 hi, const raytrace::Material& m) {
  return Box(name, hi - lo, (lo + hi) * 0.5f, m);
}

// A wall face of the room's bounding box with an optional rectangular hole: the wall is the slab
// between `lo` and `hi`; the hole spans [h0, h1] in the two in-plane axes a, b (others ignored).
void WallWithHole(const std::string& name, Vec3 lo, Vec3 hi, int axis_a, int axis_b,
                  const std::optional<std::array<float, 4>>& hole, const raytrace::Material& m,
                  std::vector<GeneratedObject>& out) {
  if (!hole) {
    out.push_back(Slab(name, lo, hi, m));
    return;
  }
  const auto [a0, a1, b0, b1] = *hole;
  auto piece = [&](const char* suffix, float pa0, float pa1, float pb0, float pb1) {
    if (pa1 - pa0 < 1e-3f || pb1 - pb0 < 1e-3f) return;
    Vec3 l = lo, h = hi;
    l[axis_a] = pa0;
    h[axis_a] = pa1;
    l[axis_b] = pb0;
    h[axis_b] = pb1;
    out.push_back(Slab(name + suffix, l, h, m));
  };
  piece("_a", lo[axis_a], a0, lo[axis_b], hi[axis_b]);
  piece("_b", a1, hi[axis_a], lo[axis_b], hi[axis_b]);
  piece("_c", a0, a1, lo[axis_b], b0);
  piece("_d", a0, a1, b1, hi[axis_b]);
}

// The CIE-overcast-like sky: radiance L_z (1 + 2 cos theta) / 3 above the horizon, 20 % of the
// horizon value below it; projected to 9 SH coefficients (world frame) times `color`.
// Its irradiance on a horizontal surface is 7 pi L_z / 9.
std::array<Vec3, 9> SkySh(double zenith_radiance, Vec3 color) {
  const sh::QuadratureRule rule = sh::GaussLegendreRule(16);
  std::array<Vec3, 9> out{};
  for (size_t i = 0; i < rule.directions.size(); ++i) {
    const sh::Vec3& d = rule.directions[i];
    const double up = d[1];
    const double l = up >= 0 ? zenith_radiance * (1 + 2 * up) / 3 : 0.2 * zenith_radiance / 3;
    const std::array<float, 9> y = raytrace::ShBasis9(
        {static_cast<float>(d[0]), static_cast<float>(d[1]), static_cast<float>(d[2])});
    for (int k = 0; k < 9; ++k) out[k] += color * static_cast<float>(rule.weights[i] * l * y[k]);
  }
  return out;
}

// SH coefficients of world-frame radiance re-expressed in a frame whose axes are the columns of
// `frame_to_world` (exact for bands 0..2 with this quadrature).
std::array<Vec3, 9> RotateSh(const std::array<Vec3, 9>& world, const Mat3& frame_to_world) {
  const sh::QuadratureRule rule = sh::GaussLegendreRule(6);
  std::array<Vec3, 9> out{};
  for (size_t i = 0; i < rule.directions.size(); ++i) {
    const Vec3 d_frame{static_cast<float>(rule.directions[i][0]),
                       static_cast<float>(rule.directions[i][1]),
                       static_cast<float>(rule.directions[i][2])};
    const std::array<float, 9> y_world = raytrace::ShBasis9(frame_to_world * d_frame);
    const std::array<float, 9> y_frame = raytrace::ShBasis9(d_frame);
    Vec3 value;
    for (int k = 0; k < 9; ++k) value += world[k] * y_world[k];
    for (int k = 0; k < 9; ++k) out[k] += value * static_cast<float>(rule.weights[i] * y_frame[k]);
  }
  return out;
}

// A point inside [lo, hi] with a margin.
bool Inside(Vec3 p, Vec3 lo, Vec3 hi, float margin) {
  for (int a = 0; a < 3; ++a) {
    if (p[a] < lo[a] + margin || p[a] > hi[a] - margin) return false;
  }
  return true;
}

// Footprint (x, z rectangle) overlap test of furniture.
struct Footprint {
  float x0, x1, z0, z1;
  bool Overlaps(const Footprint& o, float margin) const {
    return x0 < o.x1 + margin && o.x0 < x1 + margin && z0 < o.z1 + margin && o.z0 < z1 + margin;
  }
};

std::string Number(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.6g", std::abs(v) < 5e-13 ? 0.0 : v);
  return buffer;
}
std::string Triple(Vec3 v) {
  return "[" + Number(v.x) + ", " + Number(v.y) + ", " + Number(v.z) + "]";
}

void WriteText(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
  if (!out) throw ScenarioError("cannot write '" + path.string() + "'");
}

void WritePng(const std::filesystem::path& path, const cv::Mat& image) {
  if (!cv::imwrite(path.string(), image)) {
    throw ScenarioError("cannot write '" + path.string() + "'");
  }
}

cv::Mat RgbToBgrMat(const std::vector<uint8_t>& rgb, int w, int h) {
  cv::Mat m(h, w, CV_8UC3, const_cast<uint8_t*>(rgb.data()));
  cv::Mat bgr;
  cv::cvtColor(m, bgr, cv::COLOR_RGB2BGR);
  return bgr;
}

// Denoises a path-traced frame in place (linear_rgb, then srgb) guided by its first-hit albedo,
// normals and depth; pixels without an albedo to demodulate by (emitters seen directly, black
// surfaces) are left as traced.
void Denoise(raytrace::Frame& f, raytrace::ThreadPool* pool) {
  const size_t n = static_cast<size_t>(f.width) * f.height;
  internal::DenoiseGuides g;
  g.width = f.width;
  g.height = f.height;
  g.albedo = f.albedo;
  g.normal = f.normals;
  g.depth = f.depth_m;
  g.keep.assign(n, 0);
  for (size_t p = 0; p < n; ++p) {
    const float* a = &f.albedo[3 * p];
    g.keep[p] = f.depth_m[p] > 0 && a[0] == 0 && a[1] == 0 && a[2] == 0;
  }
  internal::DenoiseAtrous(g, f.linear_rgb, pool);
  for (size_t i = 0; i < f.linear_rgb.size(); ++i) {
    f.srgb[i] = raytrace::LinearToSrgb8(f.linear_rgb[i]);
  }
}

}  // namespace

uint64_t SplitSeedBase(Split split) {
  switch (split) {
    case Split::kTrain:
      return 0;
    case Split::kValidation:
      return kSplitSeedStride;
    case Split::kTest:
      return 2 * kSplitSeedStride;
  }
  return 0;
}

Split ParseSplit(const std::string& text) {
  if (text == "train") return Split::kTrain;
  if (text == "validation") return Split::kValidation;
  if (text == "test") return Split::kTest;
  throw ScenarioError("--split: expected train, validation or test, got '" + text + "'");
}

std::string SplitName(Split split) {
  switch (split) {
    case Split::kTrain:
      return "train";
    case Split::kValidation:
      return "validation";
    case Split::kTest:
      return "test";
  }
  return "?";
}

void GenerateOptions::Validate() const {
  auto require = [](bool ok, const std::string& what) {
    if (!ok) throw ScenarioError(what);
  };
  require(frames >= 1 && frames <= 600, "--frames: expected 1..600, got " + std::to_string(frames));
  require(samples_per_pixel >= 1 && samples_per_pixel <= 65536,
          "--spp: expected 1..65536, got " + std::to_string(samples_per_pixel));
  require(bounces >= 0 && bounces <= 64,
          "--bounces: expected 0..64, got " + std::to_string(bounces));
  require(probe_directions >= 64,
          "probe_directions: expected >= 64, got " + std::to_string(probe_directions));
  require(ratio_samples >= 1, "ratio_samples: expected >= 1, got " + std::to_string(ratio_samples));
  require(width >= 16 && height >= 16 && width <= 8192 && height <= 8192,
          "--size: expected 16..8192 pixels each way, got " + std::to_string(width) + "x" +
              std::to_string(height));
  require(threads >= 1, "--threads: expected >= 1, got " + std::to_string(threads));
}

GeneratedScene GenerateScene(uint64_t seed, Split split, const GenerateOptions& options) {
  options.Validate();
  Rng rng(SplitMix64(seed ^ 0x5EED5CE7Eull));
  GeneratedScene s;
  s.seed = seed;
  char name[64];
  std::snprintf(name, sizeof name, "%s_%07llu", SplitName(split).c_str(),
                static_cast<unsigned long long>(seed));
  s.name = name;

  // --- The room (or an open courtyard) -------------------------------------------------------
  const bool courtyard = rng.Uniform() < 0.25;
  s.room = courtyard ? "courtyard" : "room";
  const float W = static_cast<float>(rng.Uniform(3.2, 7.0));
  const float D = static_cast<float>(rng.Uniform(3.2, 7.0));
  const float H = courtyard ? static_cast<float>(rng.Uniform(2.5, 4.5))
                            : static_cast<float>(rng.Uniform(2.4, 3.2));
  s.room_size = {W, H, D};
  const Vec3 lo{0, 0, 0};
  const Vec3 hi{W, H, D};

  raytrace::Material floor_m;
  floor_m.albedo = RandomAlbedo(rng, 0.15, 0.6, 0.5);
  MaybePattern(rng, 0.7, floor_m);
  MaybeGloss(rng, 0.3, floor_m);
  raytrace::Material wall_m;
  wall_m.albedo = RandomAlbedo(rng, 0.45, 0.85, 0.25);
  MaybePattern(rng, 0.25, wall_m);
  raytrace::Material ceiling_m;
  ceiling_m.albedo = RandomAlbedo(rng, 0.65, 0.9, 0.08);

  // --- Lights: which kinds ---------------------------------------------------------------------
  bool sun = false;
  int lamps = 0;
  if (courtyard) {
    sun = true;
    lamps = rng.Uniform() < 0.15 ? 1 : 0;
  } else {
    const double pick = rng.Uniform();
    if (pick < 0.3) {
      sun = true;
    } else if (pick < 0.75) {
      lamps = 1 + static_cast<int>(rng.Uniform() * 3);
    } else {
      sun = true;
      lamps = 1 + static_cast<int>(rng.Uniform() * 2);
    }
  }

  // --- The table and the support of the insertions -------------------------------------------
  const float table_w = static_cast<float>(rng.Uniform(0.8, 1.6));
  const float table_d = static_cast<float>(rng.Uniform(0.6, 1.0));
  const float table_h = static_cast<float>(rng.Uniform(0.68, 0.8));
  const float table_x = static_cast<float>(rng.Uniform(1.0 + table_w / 2, W - 1.0 - table_w / 2));
  const float table_z = static_cast<float>(rng.Uniform(1.0 + table_d / 2, D - 1.0 - table_d / 2));
  raytrace::Material table_m;
  table_m.albedo = RandomAlbedo(rng, 0.2, 0.8, 0.6);
  MaybePattern(rng, 0.4, table_m);
  MaybeGloss(rng, 0.35, table_m);
  const float top = 0.04f;
  s.objects.push_back(
      Box("table_top", {table_w, top, table_d}, {table_x, table_h - top / 2, table_z}, table_m));
  for (int k = 0; k < 4; ++k) {
    const float lx = table_x + (k % 2 ? 1 : -1) * (table_w / 2 - 0.06f);
    const float lz = table_z + (k / 2 ? 1 : -1) * (table_d / 2 - 0.06f);
    s.objects.push_back(Box("table_leg" + std::to_string(k), {0.05f, table_h - top, 0.05f},
                            {lx, (table_h - top) / 2, lz}, table_m));
  }
  const Footprint table_fp{table_x - table_w / 2, table_x + table_w / 2, table_z - table_d / 2,
                           table_z + table_d / 2};
  const bool on_floor = rng.Uniform() < 0.2;
  Vec3 support;
  if (on_floor) {
    // Beside the table, on the floor, inside the room.
    const double side = rng.Uniform() < 0.5 ? -1 : 1;
    support = {table_x, 0,
               static_cast<float>(table_z + side * (table_d / 2 + rng.Uniform(0.35, 0.6)))};
    support.z = std::clamp(support.z, 0.5f, D - 0.5f);
  } else {
    support = {table_x + static_cast<float>(rng.Uniform(-0.15, 0.15)) * table_w, table_h,
               table_z + static_cast<float>(rng.Uniform(-0.1, 0.1)) * table_d};
  }
  s.support_point = support;

  // --- Insertion objects ----------------------------------------------------------------------
  const int insertions = rng.Uniform() < 0.3 ? 2 : 1;
  for (int k = 0; k < insertions; ++k) {
    InsertionObject o;
    o.shape = rng.Uniform() < 0.6 ? "sphere" : "box";
    o.albedo = rng.Uniform() < 0.5 ? Vec3{1, 1, 1} * static_cast<float>(rng.Uniform(0.3, 0.85))
                                   : RandomAlbedo(rng, 0.3, 0.85, 0.8);
    Vec3 base = support;
    if (k == 1) {
      const double a = rng.Uniform(0, 2 * kPi);
      const float r = static_cast<float>(rng.Uniform(0.22, 0.3));
      base.x += r * static_cast<float>(std::cos(a));
      base.z += r * static_cast<float>(std::sin(a)) * 0.6f;
      if (!on_floor) {
        base.x = std::clamp(base.x, table_fp.x0 + 0.12f, table_fp.x1 - 0.12f);
        base.z = std::clamp(base.z, table_fp.z0 + 0.12f, table_fp.z1 - 0.12f);
      }
    }
    if (o.shape == "sphere") {
      o.radius = static_cast<float>(rng.Uniform(0.05, 0.11));
      o.position = base + Vec3{0, o.radius, 0};
    } else {
      o.size = {static_cast<float>(rng.Uniform(0.08, 0.2)),
                static_cast<float>(rng.Uniform(0.06, 0.18)),
                static_cast<float>(rng.Uniform(0.08, 0.2))};
      const double yaw = rng.Uniform(0, kPi);
      o.rotation = {0, std::sin(yaw / 2), 0, std::cos(yaw / 2)};
      o.position = base + Vec3{0, o.size.y / 2, 0};
    }
    s.insertions.push_back(o);
  }

  // --- Clutter on the table, away from the insertions ----------------------------------------
  const int clutter = static_cast<int>(rng.Uniform() * 5);
  for (int k = 0; k < clutter; ++k) {
    for (int attempt = 0; attempt < 20; ++attempt) {
      const Vec3 p{static_cast<float>(rng.Uniform(table_fp.x0 + 0.08, table_fp.x1 - 0.08)), table_h,
                   static_cast<float>(rng.Uniform(table_fp.z0 + 0.08, table_fp.z1 - 0.08))};
      bool clear = true;
      for (const InsertionObject& o : s.insertions) {
        const float dx = p.x - o.position.x, dz = p.z - o.position.z;
        if (dx * dx + dz * dz < 0.3f * 0.3f) clear = false;
      }
      if (!clear) continue;
      raytrace::Material m;
      m.albedo = RandomAlbedo(rng, 0.1, 0.85, 0.9);
      MaybePattern(rng, 0.3, m);
      MaybeGloss(rng, 0.4, m);
      GeneratedObject o;
      o.name = "clutter" + std::to_string(k);
      const double pick = rng.Uniform();
      if (pick < 0.35) {
        o = Box(o.name,
                {static_cast<float>(rng.Uniform(0.05, 0.2)),
                 static_cast<float>(rng.Uniform(0.03, 0.25)),
                 static_cast<float>(rng.Uniform(0.05, 0.2))},
                p, m, rng.Uniform(0, kPi));
        o.object_to_world.translation[1] += o.size.y / 2;
      } else if (pick < 0.6) {
        o.shape = "sphere";
        o.radius = static_cast<float>(rng.Uniform(0.03, 0.08));
        o.object_to_world = At(p + Vec3{0, o.radius, 0});
        o.material = m;
      } else if (pick < 0.88) {
        o.shape = "cylinder";
        o.radius = static_cast<float>(rng.Uniform(0.03, 0.07));
        o.height = static_cast<float>(rng.Uniform(0.06, 0.3));
        o.object_to_world = At(p);
        o.material = m;
      } else {
        o.shape = "head";  // the bust, upright, facing a random way
        o.radius = 0.075f;
        o.object_to_world = At(p, rng.Uniform(0, 2 * kPi));
        o.material = m;
      }
      s.objects.push_back(o);
      break;
    }
  }

  // --- Camera: looks at the insertions from 1-2.8 m, hand-held ----------------------------------
  s.camera.width = options.width;
  s.camera.height = options.height;
  s.camera.fx = s.camera.fy = 525.0 * options.width / 640.0;
  s.camera.cx = (options.width - 1) / 2.0;
  s.camera.cy = (options.height - 1) / 2.0;
  Vec3 target;
  for (const InsertionObject& o : s.insertions) target += o.position;
  target = target / static_cast<float>(s.insertions.size());
  Vec3 eye;
  for (int attempt = 0; attempt < 200; ++attempt) {
    const double distance = rng.Uniform(1.0, 2.8);
    const double azimuth = rng.Uniform(0, 2 * kPi);
    const double height = rng.Uniform(1.1, std::min(1.9, H - 0.3));
    const double drop = height - target.y;
    const double horizontal = std::sqrt(std::max(0.25, distance * distance - drop * drop));
    eye = {target.x + static_cast<float>(horizontal * std::cos(azimuth)),
           static_cast<float>(height),
           target.z + static_cast<float>(horizontal * std::sin(azimuth))};
    if (Inside(eye, lo, hi, 0.35f) || attempt == 199) break;
  }

  // --- Furniture along the walls (not between the camera and the table) ---------------------
  std::vector<Footprint> taken{table_fp, {eye.x - 0.4f, eye.x + 0.4f, eye.z - 0.4f, eye.z + 0.4f}};
  const int furniture =
      courtyard ? static_cast<int>(rng.Uniform() * 3) : 2 + static_cast<int>(rng.Uniform() * 5);
  for (int k = 0; k < furniture; ++k) {
    raytrace::Material m;
    m.albedo = RandomAlbedo(rng, 0.1, 0.8, 0.7);
    MaybePattern(rng, 0.35, m);
    MaybeGloss(rng, 0.2, m);
    const double pick = rng.Uniform();
    for (int attempt = 0; attempt < 30; ++attempt) {
      Vec3 size;
      std::string kind;
      if (pick < 0.3) {
        kind = "shelf";
        size = {static_cast<float>(rng.Uniform(0.6, 1.4)),
                static_cast<float>(rng.Uniform(1.2, 2.0)),
                static_cast<float>(rng.Uniform(0.3, 0.45))};
      } else if (pick < 0.5) {
        kind = "sofa";
        size = {static_cast<float>(rng.Uniform(1.4, 2.2)), 0.45f,
                static_cast<float>(rng.Uniform(0.8, 0.95))};
      } else if (pick < 0.8) {
        kind = "box";
        size = {static_cast<float>(rng.Uniform(0.3, 0.8)),
                static_cast<float>(rng.Uniform(0.3, 0.9)),
                static_cast<float>(rng.Uniform(0.3, 0.8))};
      } else {
        kind = rng.Uniform() < 0.5 ? "cylinder" : "ball";
        const float r = static_cast<float>(rng.Uniform(0.15, 0.3));
        size = {2 * r, kind == "ball" ? 2 * r : static_cast<float>(rng.Uniform(0.4, 1.0)), 2 * r};
      }
      // Against a random wall, or anywhere for small items.
      const int wall = static_cast<int>(rng.Uniform() * 4);
      Vec3 c{static_cast<float>(rng.Uniform(size.x / 2 + 0.05, W - size.x / 2 - 0.05)), 0,
             static_cast<float>(rng.Uniform(size.z / 2 + 0.05, D - size.z / 2 - 0.05))};
      if (kind == "shelf" || kind == "sofa") {
        if (wall == 0) c.z = size.z / 2 + 0.02f;
        if (wall == 1) c.z = D - size.z / 2 - 0.02f;
        if (wall >= 2) {
          std::swap(size.x, size.z);
          c.x = wall == 2 ? size.x / 2 + 0.02f : W - size.x / 2 - 0.02f;
          c.z = std::clamp(c.z, size.z / 2 + 0.05f, D - size.z / 2 - 0.05f);
        }
      }
      const Footprint fp{c.x - size.x / 2, c.x + size.x / 2, c.z - size.z / 2, c.z + size.z / 2};
      if (size.x > W - 0.2f || size.z > D - 0.2f) continue;
      bool free = true;
      for (const Footprint& t : taken) free = free && !fp.Overlaps(t, 0.25f);
      // Keep the camera's line of sight to the target clear of furniture (a 2D segment test).
      for (int step = 0; step <= 20 && free; ++step) {
        const float a = step / 20.0f;
        const float px = eye.x + (target.x - eye.x) * a, pz = eye.z + (target.z - eye.z) * a;
        if (px > fp.x0 - 0.1f && px < fp.x1 + 0.1f && pz > fp.z0 - 0.1f && pz < fp.z1 + 0.1f) {
          free = false;
        }
      }
      if (!free) continue;
      taken.push_back(fp);
      const std::string n = kind + std::to_string(k);
      if (kind == "sofa") {
        const bool along_x = size.x > size.z;
        s.objects.push_back(Box(n + "_seat", size, c + Vec3{0, size.y / 2, 0}, m));
        Vec3 back_size = along_x ? Vec3{size.x, 0.45f, 0.2f} : Vec3{0.2f, 0.45f, size.z};
        Vec3 back_c = c + Vec3{0, size.y + 0.225f, 0};
        if (along_x)
          back_c.z += (c.z < D / 2 ? -1 : 1) * (size.z / 2 - 0.1f);
        else
          back_c.x += (c.x < W / 2 ? -1 : 1) * (size.x / 2 - 0.1f);
        s.objects.push_back(Box(n + "_back", back_size, back_c, m));
      } else if (kind == "shelf") {
        // A frame with boards; books as small boxes on them.
        s.objects.push_back(Box(n, size, c + Vec3{0, size.y / 2, 0}, m));
      } else if (kind == "cylinder") {
        GeneratedObject o;
        o.name = n;
        o.shape = "cylinder";
        o.radius = size.x / 2;
        o.height = size.y;
        o.object_to_world = At(c);
        o.material = m;
        s.objects.push_back(o);
      } else if (kind == "ball") {
        GeneratedObject o;
        o.name = n;
        o.shape = "sphere";
        o.radius = size.x / 2;
        o.object_to_world = At(c + Vec3{0, o.radius, 0});
        o.material = m;
        s.objects.push_back(o);
      } else {
        s.objects.push_back(Box(n, size, c + Vec3{0, size.y / 2, 0}, m, rng.Uniform(-0.3, 0.3)));
      }
      break;
    }
  }

  // --- Sun and sky --------------------------------------------------------------------------
  const float key_irradiance = static_cast<float>(kPi * 2.0);  // direct light on the target area
  std::optional<std::array<float, 4>> holes[5];                // walls z0, z1, x0, x1, ceiling
  if (sun) {
    const double elevation = rng.Uniform(10, 80) * kDeg;
    const double azimuth = rng.Uniform(0, 2 * kPi);
    const Vec3 d{static_cast<float>(std::cos(elevation) * std::cos(azimuth)),
                 static_cast<float>(std::sin(elevation)),
                 static_cast<float>(std::cos(elevation) * std::sin(azimuth))};
    // Sun-to-sky ratio from clear (10) to overcast (0.05): E_sun / E_sky on a horizontal surface.
    const double ratio = std::pow(10.0, rng.Uniform(-1.3, 1.0));
    const double kelvin = 3200 + 2800 * std::sin(elevation);
    raytrace::DirectionalLight l;
    l.direction = d;
    l.irradiance = raytrace::BlackbodyRgb(kelvin) * key_irradiance;
    l.angular_radius = 0.0047f;
    s.suns.push_back(l);
    const double e_sky = key_irradiance * std::sin(elevation) / ratio;
    const Vec3 sky_color =
        raytrace::BlackbodyRgb(ratio > 1 ? 6500 + 1500 * std::log10(ratio) * 2 : 6500);
    s.sky_sh = SkySh(9 * e_sky / (7 * kPi), sky_color);
    if (!courtyard) {
      // A window (or a skylight) where the ray from the insertions towards the sun leaves the
      // room, so that the sun reaches them.
      float t_best = 1e9f;
      int face = -1;
      for (int f = 0; f < 5; ++f) {
        const int axis = f < 2 ? 2 : (f < 4 ? 0 : 1);
        const float plane = f == 0 ? 0 : f == 1 ? D : f == 2 ? 0 : f == 3 ? W : H;
        if (std::abs(d[axis]) < 1e-4f) continue;
        const float t = (plane - target[axis]) / d[axis];
        if (t > 0 && t < t_best) {
          t_best = t;
          face = f;
        }
      }
      const Vec3 exit = target + d * t_best;
      const int a = face < 2 ? 0 : (face < 4 ? 2 : 0);
      const int b = face < 4 ? 1 : 2;
      const float wa = static_cast<float>(rng.Uniform(1.0, 2.0)) / 2;
      const float wb = static_cast<float>(rng.Uniform(0.8, 1.5)) / 2;
      const float amax = a == 0 ? W : D;
      const float bmax = b == 1 ? H : D;
      const float ca = std::clamp(exit[a], 0.15f + wa, amax - 0.15f - wa);
      const float cb = std::clamp(exit[b], 0.15f + wb, bmax - 0.15f - wb);
      holes[face] = std::array<float, 4>{ca - wa, ca + wa, cb - wb, cb + wb};
    }
  } else if (rng.Uniform() < 0.5) {
    // A dim overcast daylight through a window on one wall.
    s.sky_sh = SkySh(rng.Uniform(0.05, 0.3) * key_irradiance / kPi, raytrace::BlackbodyRgb(7000));
    const int face = static_cast<int>(rng.Uniform() * 4);
    const float amax = face < 2 ? W : D;
    const float c = static_cast<float>(rng.Uniform(1.0, amax - 1.0));
    holes[face] = std::array<float, 4>{c - 0.6f, c + 0.6f, 0.9f, std::min(H - 0.3f, 2.2f)};
  }

  // --- Walls, floor, ceiling ------------------------------------------------------------------
  const float pad = courtyard ? 8.0f : 0.0f;  // the courtyard floor extends beyond its walls
  s.objects.push_back(Slab("floor", {-pad - kWall, -kWall, -pad - kWall},
                           {W + pad + kWall, 0, D + pad + kWall}, floor_m));
  if (courtyard) {
    // Two or three walls of the courtyard; the rest is open.
    const int walls = 2 + static_cast<int>(rng.Uniform() * 2);
    if (walls >= 1)
      WallWithHole("wall_z0", {-kWall, 0, -kWall}, {W + kWall, H, 0}, 0, 1, {}, wall_m, s.objects);
    if (walls >= 2) WallWithHole("wall_x0", {-kWall, 0, 0}, {0, H, D}, 2, 1, {}, wall_m, s.objects);
    if (walls >= 3)
      WallWithHole("wall_x1", {W, 0, 0}, {W + kWall, H, D}, 2, 1, {}, wall_m, s.objects);
  } else {
    WallWithHole("wall_z0", {-kWall, 0, -kWall}, {W + kWall, H, 0}, 0, 1, holes[0], wall_m,
                 s.objects);
    WallWithHole("wall_z1", {-kWall, 0, D}, {W + kWall, H, D + kWall}, 0, 1, holes[1], wall_m,
                 s.objects);
    WallWithHole("wall_x0", {-kWall, 0, 0}, {0, H, D}, 2, 1, holes[2], wall_m, s.objects);
    WallWithHole("wall_x1", {W, 0, 0}, {W + kWall, H, D}, 2, 1, holes[3], wall_m, s.objects);
    WallWithHole("ceiling", {-kWall, H, -kWall}, {W + kWall, H + kWall, D + kWall}, 0, 2, holes[4],
                 ceiling_m, s.objects);
  }

  // --- Lamps: point or area, white (2700-6500 K) or coloured, 0.5-3 m from the insertions ---
  bool any_point = false, any_area = false;
  for (int k = 0; k < lamps; ++k) {
    Vec3 color = raytrace::BlackbodyRgb(rng.Uniform(2700, 6500));
    if (rng.Uniform() < 0.3) color = color * Hue(rng.Uniform(), rng.Uniform(0.4, 0.8));
    color = color / std::max(1e-3f, Luminance(color));
    const float share = k == 0 ? 1.0f : static_cast<float>(rng.Uniform(0.2, 0.7));
    const float irradiance = key_irradiance * share * (sun ? 0.6f : 1.0f);
    Vec3 p;
    for (int attempt = 0; attempt < 50; ++attempt) {
      const double distance = rng.Uniform(0.5, 3.0);
      const double elevation = rng.Uniform(25, 80) * kDeg;
      const double azimuth = rng.Uniform(0, 2 * kPi);
      p = target + Vec3{static_cast<float>(distance * std::cos(elevation) * std::cos(azimuth)),
                        static_cast<float>(distance * std::sin(elevation)),
                        static_cast<float>(distance * std::cos(elevation) * std::sin(azimuth))};
      if (Inside(p, lo, hi, 0.2f)) break;
    }
    p.x = std::clamp(p.x, 0.2f, W - 0.2f);
    p.y = std::clamp(p.y, target.y + 0.3f, H - 0.15f);
    p.z = std::clamp(p.z, 0.2f, D - 0.2f);
    const float r2 = Dot(p - target, p - target);
    const float cos_at_target = std::max(0.2f, (p.y - target.y) / std::sqrt(r2));
    if (rng.Uniform() < 0.5) {
      any_point = true;
      s.point_lights.push_back({p, color * (irradiance * r2 / cos_at_target), true});
    } else {
      any_area = true;
      raytrace::AreaLight a;
      if (rng.Uniform() < 0.5) {
        a.shape = raytrace::AreaLight::Shape::kSphere;
        a.radius = static_cast<float>(rng.Uniform(0.04, 0.12));
        a.centre = p;
        // A sphere of radiance L seen from distance r gives irradiance L pi R^2 / r^2 (facing).
        a.radiance = color * (irradiance * r2 / (cos_at_target * float(kPi) * a.radius * a.radius));
      } else {
        // A panel under the ceiling, emitting downwards.
        a.shape = raytrace::AreaLight::Shape::kRectangle;
        const float hu = static_cast<float>(rng.Uniform(0.15, 0.6));
        const float hv = static_cast<float>(rng.Uniform(0.15, 0.6));
        a.centre = {p.x, H - 0.01f, p.z};
        a.half_u = {hu, 0, 0};
        a.half_v = {0, 0, hv};  // Cross(half_u, half_v) points down (-y)
        const Vec3 to = a.centre - target;
        const float d2 = Dot(to, to);
        const float c = std::max(0.2f, to.y / std::sqrt(d2));
        const float area = 4 * hu * hv;
        a.radiance = color * (irradiance * d2 / (c * c * area));
      }
      s.area_lights.push_back(a);
    }
  }
  const int kinds = (sun ? 1 : 0) + (any_point ? 1 : 0) + (any_area ? 1 : 0);
  s.light_type = kinds > 1 ? "mixed" : sun ? "directional" : any_point ? "point" : "area";

  // --- Camera path: a slow drift with hand-held shake (30 fps) --------------------------------
  const Vec3 drift{static_cast<float>(rng.Uniform(-0.25, 0.25)),
                   static_cast<float>(rng.Uniform(-0.05, 0.05)),
                   static_cast<float>(rng.Uniform(-0.25, 0.25))};
  const double shake_hz = rng.Uniform(0.8, 2.0);
  const double phase[3] = {rng.Uniform(0, 2 * kPi), rng.Uniform(0, 2 * kPi),
                           rng.Uniform(0, 2 * kPi)};
  const float shake_m = static_cast<float>(rng.Uniform(0.004, 0.015));
  const double roll0 = rng.Uniform(-3, 3) * kDeg;
  for (int i = 0; i < options.frames; ++i) {
    const double t = i / kFps;
    Vec3 e = eye + drift * static_cast<float>(t);
    for (int a = 0; a < 3; ++a) {
      e[a] += shake_m * static_cast<float>(std::sin(2 * kPi * shake_hz * t + phase[a]));
    }
    const Vec3 look =
        target + Vec3{0, 0.02f, 0} +
        Vec3{1, 0.5f, 1} *
            (shake_m * 2 * static_cast<float>(std::sin(2 * kPi * shake_hz * 1.3 * t + phase[1])));
    Transform pose = Transform::LookAt(e, look, {0, 1, 0});
    pose.rotation = pose.rotation * Mat3::AxisAngle({0, 0, 1}, roll0 + 0.01 * std::sin(3 * t));
    s.camera_path.push_back(pose);
  }

  // The insertions must be seen: clutter or furniture between the first camera and an
  // insertion's centre or top is removed (the table, walls and floor stay).
  for (int pass = 0; pass < 4; ++pass) {
    raytrace::Scene check;
    BuildScene(s, false, &check);
    const Transform& first = s.camera_path.front();
    const Vec3 from{static_cast<float>(first.translation[0]),
                    static_cast<float>(first.translation[1]),
                    static_cast<float>(first.translation[2])};
    std::vector<raytrace::Ray> rays;
    for (const InsertionObject& o : s.insertions) {
      const float top = o.shape == "sphere" ? o.radius : o.size.y / 2;
      for (const Vec3 p : {o.position, o.position + Vec3{0, 0.8f * top, 0}}) {
        rays.push_back({from, p - from, 0, 1});
      }
    }
    std::vector<raytrace::Hit> hits(rays.size());
    check.Intersect(rays, hits);
    std::set<int> blockers;
    for (const raytrace::Hit& hit : hits) {
      if (hit.object < 0) continue;
      const std::string& n = s.objects[static_cast<size_t>(hit.object)].name;
      if (n.starts_with("table") || n.starts_with("wall") || n == "floor" ||
          n.starts_with("ceiling")) {
        continue;
      }
      blockers.insert(hit.object);
    }
    if (blockers.empty()) break;
    for (auto it = blockers.rbegin(); it != blockers.rend(); ++it) {
      s.objects.erase(s.objects.begin() + *it);
    }
  }

  // Kinect v1-like depth (as the shipped room_dynamic scenario), valid 0.4-6 m.
  s.sensor.depth_min_m = 0.4;
  s.sensor.depth_max_m = 6.0;
  s.sensor.depth_noise = true;
  s.sensor.depth_holes = true;
  s.sensor.quantisation = 0.00285;
  s.sensor.dropout = 0.002;
  return s;
}

void BuildScene(const GeneratedScene& scene, bool with_insertions, raytrace::Scene* out) {
  uint32_t id = 1;
  for (const GeneratedObject& o : scene.objects) {
    raytrace::Mesh mesh;
    Transform placement = o.object_to_world;
    if (o.shape == "box") {
      mesh = raytrace::MakeBox(o.size);
    } else if (o.shape == "sphere") {
      mesh = raytrace::MakeSphere(o.radius, 32);
    } else if (o.shape == "cylinder") {
      mesh = raytrace::MakeCylinder(o.radius, o.height, 24);
    } else if (o.shape == "head") {
      // The bust stands upright (face frame y down -> world y up) on its lowest point.
      raytrace::HeadModel head = raytrace::MakeHead(o.material.albedo, 48);
      Transform upright;
      upright.rotation = Mat3::AxisAngle({1, 0, 0}, kPi);
      head.mesh.TransformBy(upright);
      const auto bounds = head.mesh.Bounds();
      Transform lift;
      lift.translation = {0, -bounds[0].y, 0};
      head.mesh.TransformBy(lift);
      mesh = std::move(head.mesh);
    } else {
      throw ScenarioError(scene.name + ": object '" + o.name + "': unknown shape '" + o.shape +
                          "'");
    }
    out->AddObject(std::move(mesh), o.material, placement, id++);
  }
  if (with_insertions) {
    for (size_t k = 0; k < scene.insertions.size(); ++k) {
      const InsertionObject& o = scene.insertions[k];
      raytrace::Material m;
      m.albedo = o.albedo;
      Transform t;
      t.translation = {o.position.x, o.position.y, o.position.z};
      raytrace::Mesh mesh;
      if (o.shape == "sphere") {
        mesh = raytrace::MakeSphere(o.radius, 64);
      } else {
        mesh = raytrace::MakeBox(o.size);
        t.rotation =
            Mat3::FromQuaternion(o.rotation[3], o.rotation[0], o.rotation[1], o.rotation[2]);
      }
      out->AddObject(std::move(mesh), m, t, kInsertionIdBase + static_cast<uint32_t>(k));
    }
  }
  out->directional_lights() = scene.suns;
  out->point_lights() = scene.point_lights;
  out->area_lights() = scene.area_lights;
  out->environment().sh = scene.sky_sh;
  out->environment().scale = 1;
  out->Commit();
}

GeneratedSceneSummary WriteGeneratedScene(const GeneratedScene& scene,
                                          const GenerateOptions& options,
                                          const std::string& out_dir, int scene_index) {
  options.Validate();
  namespace fs = std::filesystem;
  const auto start = std::chrono::steady_clock::now();
  const fs::path root = fs::path(out_dir) / scene.name;
  for (const char* sub : {"rgb", "depth", "rgb_inserted", "mask_object", "mask_effect"}) {
    std::error_code error;
    fs::create_directories(root / sub, error);
    if (error) {
      throw ScenarioError("cannot create '" + (root / sub).string() + "': " + error.message());
    }
  }
  raytrace::ThreadPool pool(options.threads);
  raytrace::Scene plain;
  BuildScene(scene, false, &plain);
  raytrace::Scene inserted;
  BuildScene(scene, true, &inserted);
  const int w = scene.camera.width;
  const int h = scene.camera.height;
  const size_t pixels = static_cast<size_t>(w) * h;

  raytrace::PathTraceOptions pt;
  pt.samples_per_pixel = options.samples_per_pixel;
  pt.max_bounces = options.bounces;
  pt.seed = scene.seed;

  // Fixed exposure for the scene: the first frame's mean luminance maps to 0.18 (a quick preview
  // at a quarter of the resolution).
  GeneratedSceneSummary summary;
  {
    raytrace::Camera preview = scene.camera;
    preview.width = std::max(16, w / 4);
    preview.height = std::max(16, h / 4);
    preview.fx *= preview.width / double(w);
    preview.fy *= preview.height / double(h);
    preview.cx = (preview.width - 1) / 2.0;
    preview.cy = (preview.height - 1) / 2.0;
    preview.camera_to_world = scene.camera_path.front();
    raytrace::PathTraceOptions quick = pt;
    quick.samples_per_pixel = 4;
    quick.max_bounces = std::min(2, options.bounces);
    const raytrace::Frame f = raytrace::PathTrace(plain, preview, quick, &pool);
    // The mean luminance with the brightest tenth clipped to the 90th percentile: a lamp seen
    // directly does not under-expose the frame, and the preview's noisy black pixels (which a
    // log-average would weigh heavily) do not over-expose it.
    const size_t n = f.linear_rgb.size() / 3;
    std::vector<float> l(n);
    for (size_t p = 0; p < n; ++p) {
      l[p] = std::max(
          0.0f, Luminance({f.linear_rgb[3 * p], f.linear_rgb[3 * p + 1], f.linear_rgb[3 * p + 2]}));
    }
    std::vector<float> sorted = l;
    const size_t k = std::min(n - 1, n * 9 / 10);
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(k), sorted.end());
    const float clip = sorted[k];
    double sum = 0;
    for (float v : l) sum += std::min(v, clip);
    const double key = sum / static_cast<double>(std::max<size_t>(1, n));
    summary.exposure = std::clamp(key > 0 ? 0.18 / key : 1.0, 1e-3, 1e3);
  }
  pt.exposure = static_cast<float>(summary.exposure);

  // The light probe at the insertions (without them): the oracle's light, in image units. (Area
  // lamps are hit by its rays; they block no shadow ray of this occlusion query.)
  Vec3 probe_point;
  for (const InsertionObject& o : scene.insertions) probe_point += o.position;
  probe_point = probe_point / static_cast<float>(scene.insertions.size());
  raytrace::PathTraceOptions probe = pt;
  probe.samples_per_pixel = 1;
  // Delta lights are never hit by the probe's rays: the suns become delta lights for it (their
  // disc would be a rare, huge spike) and their direct light, like the point lamps', is added
  // analytically where the probe sees them; their bounce light comes from the traced paths.
  // (IncidentRadianceSh applies probe.exposure.)
  for (auto& l : plain.directional_lights()) l.angular_radius = 0;
  std::array<Vec3, 9> probe_sh =
      raytrace::IncidentRadianceSh(plain, probe_point, options.probe_directions, probe, &pool);
  plain.directional_lights() = scene.suns;
  {
    std::vector<raytrace::Ray> rays;
    std::vector<Vec3> direct;  // irradiance of each delta light at the probe, exposure applied
    std::vector<Vec3> towards;
    for (const raytrace::DirectionalLight& l : scene.suns) {
      if (!l.enabled) continue;
      rays.push_back({probe_point, l.direction, 1e-3f, 1e30f});
      direct.push_back(l.irradiance);
      towards.push_back(l.direction);
    }
    for (const raytrace::PointLight& l : scene.point_lights) {
      if (!l.enabled) continue;
      const Vec3 d = l.position - probe_point;
      rays.push_back({probe_point, d, 1e-3f, 1 - 1e-3f});
      direct.push_back(l.intensity / Dot(d, d));
      towards.push_back(Normalize(d));
    }
    std::vector<uint8_t> visible(rays.size());
    plain.Occluded(rays, visible, &pool);
    for (size_t k = 0; k < rays.size(); ++k) {
      if (!visible[k]) continue;
      const std::array<float, 9> y = raytrace::ShBasis9(towards[k]);
      for (int c = 0; c < 9; ++c) {
        probe_sh[c] += direct[k] * (y[c] * static_cast<float>(summary.exposure));
      }
    }
  }

  // The dominant light at the probe: the sun, or the lamp of largest irradiance there.
  struct Dominant {
    int kind = -1;  // 0 sun, 1 point, 2 area
    int index = 0;
    float irradiance = 0;
  } dominant;
  for (size_t k = 0; k < scene.suns.size(); ++k) {
    const float e = Luminance(scene.suns[k].irradiance);
    if (e > dominant.irradiance) dominant = {0, static_cast<int>(k), e};
  }
  for (size_t k = 0; k < scene.point_lights.size(); ++k) {
    const Vec3 d = scene.point_lights[k].position - probe_point;
    const float e = Luminance(scene.point_lights[k].intensity) / Dot(d, d);
    if (e > dominant.irradiance) dominant = {1, static_cast<int>(k), e};
  }
  for (size_t k = 0; k < scene.area_lights.size(); ++k) {
    const raytrace::AreaLight& a = scene.area_lights[k];
    const Vec3 d = a.centre - probe_point;
    const float r2 = Dot(d, d);
    float e = 0;
    if (a.shape == raytrace::AreaLight::Shape::kSphere) {
      e = Luminance(a.radiance) * float(kPi) * a.radius * a.radius / r2;
    } else {
      const Vec3 n = Normalize(Cross(a.half_u, a.half_v));
      const float c = std::max(0.0f, Dot(n, -d) / std::sqrt(r2));
      e = Luminance(a.radiance) * 4 * Length(a.half_u) * Length(a.half_v) * c / r2;
    }
    if (e > dominant.irradiance) dominant = {2, static_cast<int>(k), e};
  }
  Vec3 dominant_world;
  if (dominant.kind == 0) dominant_world = scene.suns[dominant.index].direction;
  if (dominant.kind == 1) {
    dominant_world = Normalize(scene.point_lights[dominant.index].position - probe_point);
  }
  if (dominant.kind == 2) {
    dominant_world = Normalize(scene.area_lights[dominant.index].centre - probe_point);
  }

  std::ostringstream rgb_txt, depth_txt, gt_txt, truth;
  rgb_txt << "# color images\n# generated scene " << scene.name << "\n# timestamp filename\n";
  depth_txt << "# depth maps (5000 units per metre)\n# generated scene " << scene.name
            << "\n# timestamp filename\n";
  gt_txt << "# ground truth trajectory (camera -> world, optical frame)\n# generated scene "
         << scene.name << "\n# timestamp tx ty tz qx qy qz qw\n";
  truth << "{\"light_type\": \"" << scene.light_type << "\", \"scene\": \"" << scene.name
        << "\", \"exposure\": " << Number(summary.exposure)
        << ", \"units\": \"linear image units (exposure applied), camera frame\",\n \"frames\": [";

  const uint64_t depth_seed = SplitMix64(scene.seed) ^ 0xD3E7ull;
  std::vector<uint16_t> depth_mm(pixels);
  for (int i = 0; i < options.frames; ++i) {
    char stamp[32];
    std::snprintf(stamp, sizeof stamp, "%.6f", 1.0 + i / kFps);
    const std::string file = std::string(stamp) + ".png";
    raytrace::Camera camera = scene.camera;
    camera.camera_to_world = scene.camera_path[i];
    raytrace::PathTraceOptions frame_options = pt;
    frame_options.frame_index = static_cast<uint64_t>(i);
    raytrace::Frame a = raytrace::PathTrace(plain, camera, frame_options, &pool);
    raytrace::Frame b = raytrace::PathTrace(inserted, camera, frame_options, &pool);
    if (options.denoise) {
      Denoise(a, &pool);
      Denoise(b, &pool);
    }

    // The dominant light alone, direct only: its image-space share of the light.
    double direct_to_ambient = 0;
    if (dominant.kind >= 0) {
      raytrace::Scene& s = plain;
      const auto suns = s.directional_lights();
      const auto points = s.point_lights();
      const auto areas = s.area_lights();
      const auto environment = s.environment();
      for (auto& l : s.directional_lights()) l.enabled = false;
      for (auto& l : s.point_lights()) l.enabled = false;
      for (auto& l : s.area_lights()) l.enabled = false;
      s.environment().scale = 0;
      if (dominant.kind == 0) s.directional_lights()[dominant.index].enabled = true;
      if (dominant.kind == 1) s.point_lights()[dominant.index].enabled = true;
      if (dominant.kind == 2) s.area_lights()[dominant.index].enabled = true;
      raytrace::PathTraceOptions direct = frame_options;
      direct.samples_per_pixel = options.ratio_samples;
      direct.max_bounces = 0;
      const raytrace::Frame c = raytrace::PathTrace(s, camera, direct, &pool);
      s.directional_lights() = suns;
      s.point_lights() = points;
      s.area_lights() = areas;
      s.environment() = environment;
      double direct_sum = 0, total_sum = 0;
      for (size_t p = 0; p < pixels; ++p) {
        if (a.depth_m[p] <= 0) continue;  // the sky and lamps seen directly are not shading
        direct_sum +=
            Luminance({c.linear_rgb[3 * p], c.linear_rgb[3 * p + 1], c.linear_rgb[3 * p + 2]});
        total_sum +=
            Luminance({a.linear_rgb[3 * p], a.linear_rgb[3 * p + 1], a.linear_rgb[3 * p + 2]});
      }
      const double rest = std::max(1e-9, total_sum - direct_sum);
      direct_to_ambient = std::min(1e3, direct_sum / rest);
    }

    // Masks: the objects where they are the first surface seen; their effect elsewhere where the
    // smoothed luminance changes by more than 2 % (+ a small absolute floor against path noise).
    cv::Mat mask_object(h, w, CV_8UC1, cv::Scalar(0));
    // Smoothing over the pixels that are not the objects only (a normalised box filter), so the
    // objects' own change does not bleed into a ring around them.
    cv::Mat diff(h, w, CV_32FC1), level(h, w, CV_32FC1), outside(h, w, CV_32FC1);
    int object_pixels = 0;
    for (size_t p = 0; p < pixels; ++p) {
      const bool object = b.object_ids[p] >= kInsertionIdBase &&
                          b.object_ids[p] < kInsertionIdBase + scene.insertions.size();
      const float la =
          Luminance({a.linear_rgb[3 * p], a.linear_rgb[3 * p + 1], a.linear_rgb[3 * p + 2]});
      const float lb =
          Luminance({b.linear_rgb[3 * p], b.linear_rgb[3 * p + 1], b.linear_rgb[3 * p + 2]});
      mask_object.data[p] = object ? 255 : 0;
      object_pixels += object;
      reinterpret_cast<float*>(diff.data)[p] = object ? 0 : lb - la;
      reinterpret_cast<float*>(level.data)[p] = object ? 0 : la;
      reinterpret_cast<float*>(outside.data)[p] = object ? 0 : 1;
    }
    cv::Mat diff_s, level_s, outside_s;
    cv::blur(diff, diff_s, cv::Size(7, 7));
    cv::blur(level, level_s, cv::Size(7, 7));
    cv::blur(outside, outside_s, cv::Size(7, 7));
    cv::Mat mask_effect(h, w, CV_8UC1, cv::Scalar(0));
    for (size_t p = 0; p < pixels; ++p) {
      if (mask_object.data[p]) continue;
      const float k = std::max(1e-6f, reinterpret_cast<float*>(outside_s.data)[p]);
      const float d = std::abs(reinterpret_cast<float*>(diff_s.data)[p]) / k;
      const float l = reinterpret_cast<float*>(level_s.data)[p] / k;
      if (d > 0.02f * l + 0.002f) mask_effect.data[p] = 255;
    }
    if (object_pixels > 0) ++summary.frames_object_visible;

    // Kinect-like depth of the real scene (5000 units per metre, the TUM convention).
    const uint64_t frame_seed = depth_seed ^ SplitMix64(static_cast<uint64_t>(i) + 1);
    pool.ParallelFor(static_cast<size_t>(h), [&](size_t row) {
      Rng rng(frame_seed ^ SplitMix64(row + 0xA5A5ull));
      internal::SensorDepthRow(a.depth_m.data(), w, h, static_cast<int>(row), scene.sensor, rng,
                               &depth_mm[row * w]);
    });
    cv::Mat depth(h, w, CV_16UC1);
    for (size_t p = 0; p < pixels; ++p) {
      reinterpret_cast<uint16_t*>(depth.data)[p] =
          static_cast<uint16_t>(std::min<uint32_t>(65535, depth_mm[p] * 5u));
    }

    WritePng(root / "rgb" / file, RgbToBgrMat(a.srgb, w, h));
    WritePng(root / "rgb_inserted" / file, RgbToBgrMat(b.srgb, w, h));
    WritePng(root / "depth" / file, depth);
    WritePng(root / "mask_object" / file, mask_object);
    WritePng(root / "mask_effect" / file, mask_effect);
    rgb_txt << stamp << " rgb/" << file << "\n";
    depth_txt << stamp << " depth/" << file << "\n";
    const Transform& pose = scene.camera_path[i];
    const std::array<double, 4> q = pose.rotation.ToQuaternion();  // w x y z
    gt_txt << stamp << " " << Number(pose.translation[0]) << " " << Number(pose.translation[1])
           << " " << Number(pose.translation[2]) << " " << Number(q[1]) << " " << Number(q[2])
           << " " << Number(q[3]) << " " << Number(q[0]) << "\n";

    const Mat3 world_to_camera = pose.rotation.Transposed();
    truth << (i ? ",\n  " : "\n  ") << "{\"timestamp\": \"" << stamp
          << "\", \"direction_camera\": ";
    if (dominant.kind >= 0) {
      truth << Triple(Normalize(world_to_camera * dominant_world));
    } else {
      truth << "null";
    }
    truth << ", \"direct_to_ambient\": " << Number(direct_to_ambient) << ", \"sh_camera\": [";
    const std::array<Vec3, 9> sh_camera = RotateSh(probe_sh, pose.rotation);
    for (int k = 0; k < 9; ++k) truth << (k ? ", " : "") << Triple(sh_camera[k]);
    truth << "], \"object_pixels\": " << object_pixels << "}";
    if (options.progress) options.progress(scene_index, i + 1, options.frames);
  }
  truth << "\n]}\n";

  WriteText(root / "rgb.txt", rgb_txt.str());
  WriteText(root / "depth.txt", depth_txt.str());
  WriteText(root / "groundtruth.txt", gt_txt.str());
  WriteText(root / "truth.json", truth.str());

  std::ostringstream cam;
  const raytrace::Camera& c = scene.camera;
  cam << "image_width: " << c.width << "\nimage_height: " << c.height
      << "\ncamera_name: generated\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [" << Number(c.fx)
      << ", 0, " << Number(c.cx) << ", 0, " << Number(c.fy) << ", " << Number(c.cy)
      << ", 0, 0, 1]\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n"
         "  data: [0, 0, 0, 0, 0]\nrectification_matrix:\n  rows: 3\n  cols: 3\n"
         "  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\nprojection_matrix:\n  rows: 3\n  cols: 4\n  data: ["
      << Number(c.fx) << ", 0, " << Number(c.cx) << ", 0, 0, " << Number(c.fy) << ", "
      << Number(c.cy) << ", 0, 0, 0, 1, 0]\n";
  WriteText(root / "camera_info.yaml", cam.str());

  std::ostringstream ins;
  ins << "# Ground-truth insertions of generated scene " << scene.name
      << " (world frame of groundtruth.txt, metres)\nobjects:\n";
  for (const InsertionObject& o : scene.insertions) {
    ins << "  - shape: " << o.shape << "\n";
    if (o.shape == "sphere") {
      ins << "    radius: " << Number(o.radius) << "\n";
    } else {
      ins << "    size: " << Triple(o.size) << "\n";
    }
    ins << "    albedo: " << Triple(o.albedo) << "\n    position: " << Triple(o.position) << "\n";
    if (o.shape == "box") {
      ins << "    rotation: [" << Number(o.rotation[0]) << ", " << Number(o.rotation[1]) << ", "
          << Number(o.rotation[2]) << ", " << Number(o.rotation[3]) << "]\n";
    }
  }
  WriteText(root / "insertion.yaml", ins.str());

  std::ostringstream js;
  js << "{\"name\": \"" << scene.name << "\", \"seed\": " << scene.seed << ", \"room\": \""
     << scene.room << "\", \"room_size\": " << Triple(scene.room_size) << ", \"light_type\": \""
     << scene.light_type << "\", \"objects\": " << scene.objects.size() << ", \"suns\": [";
  for (size_t k = 0; k < scene.suns.size(); ++k) {
    js << (k ? ", " : "") << "{\"direction\": " << Triple(scene.suns[k].direction)
       << ", \"irradiance\": " << Triple(scene.suns[k].irradiance) << "}";
  }
  js << "], \"point_lights\": [";
  for (size_t k = 0; k < scene.point_lights.size(); ++k) {
    js << (k ? ", " : "") << "{\"position\": " << Triple(scene.point_lights[k].position)
       << ", \"intensity\": " << Triple(scene.point_lights[k].intensity) << "}";
  }
  js << "], \"area_lights\": [";
  for (size_t k = 0; k < scene.area_lights.size(); ++k) {
    const raytrace::AreaLight& a = scene.area_lights[k];
    js << (k ? ", " : "") << "{\"shape\": \""
       << (a.shape == raytrace::AreaLight::Shape::kSphere ? "sphere" : "rectangle")
       << "\", \"centre\": " << Triple(a.centre) << ", \"radiance\": " << Triple(a.radiance) << "}";
  }
  js << "], \"sky_sh0\": " << Triple(scene.sky_sh[0])
     << ", \"exposure\": " << Number(summary.exposure) << ", \"frames\": " << options.frames
     << ", \"samples_per_pixel\": " << options.samples_per_pixel
     << ", \"bounces\": " << options.bounces << "}\n";
  WriteText(root / "scene.json", js.str());

  summary.folder = root.string();
  summary.frames = options.frames;
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace probeless::sim
