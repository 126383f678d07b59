#include "probeless/render/differential.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <span>
#include <string>

#include "probeless/raytrace/render.h"
#include "probeless/sh/sh.h"

namespace probeless::render {

namespace {

using Clock = std::chrono::steady_clock;
using raytrace::Vec3;

double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// Luminance of a white-light shading (the mean of R, G, B).
float Luminance(const std::array<float, 3>& c) { return (c[0] + c[1] + c[2]) * (1.0f / 3); }

// Reinhard et al. 2002 eq. 1: exp(mean log(delta + L)) over the valid samples of `t`.
float LogAverage(const light::TransferResult& t, const ShLightRgb& light) {
  const size_t cc = static_cast<size_t>(t.coefficient_count);
  double sum = 0;
  size_t n = 0;
  for (size_t i = 0; i < t.valid.size(); ++i) {
    if (!t.valid[i]) continue;
    const float l = Luminance(ShadeTransfer({t.transfer.data() + i * cc, cc}, light));
    sum += std::log(1e-4 + std::max(0.0f, l));
    ++n;
  }
  return n == 0 ? 1.0f : static_cast<float>(std::exp(sum / static_cast<double>(n)));
}

// The unoccluded shading of a unit normal n: sum_k (A_l / pi) Y_k(n) L_k (the analytic transfer of
// light::TransferOptions::analytic_unoccluded, Ramamoorthi & Hanrahan 2001).
std::array<float, 3> ShadeUnoccluded(const ShLightRgb& light, const Vec3& n) {
  std::array<double, 25> y{};
  sh::EvaluateBasis<double>(light.bands, n.x, n.y, n.z, y.data());
  std::array<float, 3> out{0, 0, 0};
  for (int l = 0; l < light.bands; ++l) {
    const double a = sh::ClampedCosineCoefficient(l) / std::numbers::pi;
    for (int k = l * l; k < (l + 1) * (l + 1); ++k) {
      for (int c = 0; c < 3; ++c) out[c] += static_cast<float>(a * y[k] * light.coefficients[k][c]);
    }
  }
  return out;
}

// The directional part a Y(d) of `light` along unit d (DifferentialOptions::sun_shadow): per
// channel the least-squares amplitude of the pattern Y(d) in band 1 and in bands >= 2, the smaller
// of the two, at least 0. Zero for fewer than 3 bands (nothing tells a delta from a gradient).
ShLightRgb SunPart(const ShLightRgb& light, const Vec3& d, std::array<float, 3>* amplitude) {
  ShLightRgb sun;
  sun.bands = light.bands;
  *amplitude = {0, 0, 0};
  if (light.bands < 3) return sun;
  std::array<double, 25> y{};
  sh::EvaluateBasis<double>(light.bands, d.x, d.y, d.z, y.data());
  const int cc = light.bands * light.bands;
  for (int c = 0; c < 3; ++c) {
    double num1 = 0, den1 = 0, num2 = 0, den2 = 0;
    for (int k = 1; k < cc; ++k) {
      (k < 4 ? num1 : num2) += y[k] * light.coefficients[k][c];
      (k < 4 ? den1 : den2) += y[k] * y[k];
    }
    const double a = std::min(num1 / den1, num2 / den2);
    (*amplitude)[c] = static_cast<float>(std::max(0.0, a));
  }
  for (int k = 0; k < cc; ++k) {
    for (int c = 0; c < 3; ++c) sun.coefficients[k][c] = static_cast<float>((*amplitude)[c] * y[k]);
  }
  return sun;
}

// An orthographic depth map of triangles along unit d: per texel the largest p.d of the surface
// over it (the part nearest the light), -inf where there is none.
struct SunMap {
  Vec3 d, e1, e2;
  float u0 = 0, v0 = 0, texel = 1;
  int n = 0;
  std::vector<float>* t = nullptr;
  std::vector<Vec3> uvt_;

  void Build(std::span<const RasterObject> objects, int size, std::vector<float>* storage) {
    e1 = Normalize(Cross(d, std::abs(d.x) < 0.9f ? Vec3{1, 0, 0} : Vec3{0, 1, 0}));
    e2 = Cross(d, e1);
    float lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
    // Every vertex once: (u, v, t) = (p.e1, p.e2, p.d), p in the camera frame.
    uvt_.clear();
    for (const RasterObject& o : objects) {
      for (const Vec3& q : o.mesh->positions) {
        const Vec3 p = o.object_to_camera.Apply(q);
        const float u = Dot(p, e1), v = Dot(p, e2);
        uvt_.push_back({u, v, Dot(p, d)});
        lo[0] = std::min(lo[0], u), hi[0] = std::max(hi[0], u);
        lo[1] = std::min(lo[1], v), hi[1] = std::max(hi[1], v);
      }
    }
    n = size;
    texel = std::max({hi[0] - lo[0], hi[1] - lo[1], 1e-4f}) / static_cast<float>(n - 4);
    u0 = lo[0] - 2 * texel, v0 = lo[1] - 2 * texel;  // a margin of two texels
    t = storage;
    t->assign(static_cast<size_t>(n) * n, -INFINITY);
    const float inv_texel = 1 / texel;
    size_t base = 0;
    for (const RasterObject& o : objects) {
      const raytrace::Mesh& m = *o.mesh;
      for (const auto& tri : m.triangles) {
        float pu[3], pv[3], pt[3];
        for (int i = 0; i < 3; ++i) {
          const Vec3& q = uvt_[base + tri[i]];
          pu[i] = (q.x - u0) * inv_texel - 0.5f;  // texel centres at integers
          pv[i] = (q.y - v0) * inv_texel - 0.5f;
          pt[i] = q.z;
        }
        const float area = (pu[1] - pu[0]) * (pv[2] - pv[0]) - (pu[2] - pu[0]) * (pv[1] - pv[0]);
        if (std::abs(area) < 1e-12f) continue;
        const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({pu[0], pu[1], pu[2]}))));
        const int x1 =
            std::min(n - 1, static_cast<int>(std::floor(std::max({pu[0], pu[1], pu[2]}))));
        const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({pv[0], pv[1], pv[2]}))));
        const int y1 =
            std::min(n - 1, static_cast<int>(std::floor(std::max({pv[0], pv[1], pv[2]}))));
        for (int yy = y0; yy <= y1; ++yy) {
          for (int xx = x0; xx <= x1; ++xx) {
            const float w1 =
                ((xx - pu[0]) * (pv[2] - pv[0]) - (pu[2] - pu[0]) * (yy - pv[0])) / area;
            const float w2 =
                ((pu[1] - pu[0]) * (yy - pv[0]) - (xx - pu[0]) * (pv[1] - pv[0])) / area;
            const float w0 = 1 - w1 - w2;
            if (w0 < -1e-4f || w1 < -1e-4f || w2 < -1e-4f) continue;
            float& cell = (*t)[static_cast<size_t>(yy) * n + xx];
            cell = std::max(cell, w0 * pt[0] + w1 * pt[1] + w2 * pt[2]);
          }
        }
      }
      base += m.positions.size();
    }
  }

  // The visibility of point p towards d: the share of the 3 x 3 texels around it whose surface
  // lies more than `bias` nearer the light than p (percentage-closer filtering).
  float Visibility(const Vec3& p, float bias) const {
    const int cu = static_cast<int>(std::lround((Dot(p, e1) - u0) / texel - 0.5f));
    const int cv = static_cast<int>(std::lround((Dot(p, e2) - v0) / texel - 0.5f));
    if (cu < -1 || cv < -1 || cu > n || cv > n) return 1;
    const float along = Dot(p, d) + bias;
    int blocked = 0;
    for (int j = cv - 1; j <= cv + 1; ++j) {
      for (int i = cu - 1; i <= cu + 1; ++i) {
        if (i < 0 || j < 0 || i >= n || j >= n) continue;
        blocked += (*t)[static_cast<size_t>(j) * n + i] > along;
      }
    }
    return 1 - blocked / 9.0f;
  }
};

}  // namespace

void RasteriseObjects(const light::GeometryView& real, std::span<const RasterObject> objects,
                      VirtualGeometry* out) {
  light::ValidateGeometryView(real, "render::RasteriseObjects");
  const int w = real.width, h = real.height;
  const size_t pixels = static_cast<size_t>(w) * h;
  out->width = w;
  out->height = h;
  out->depth.assign(real.depth.begin(), real.depth.end());
  out->normals.assign(real.normals.begin(), real.normals.end());
  if (real.colour.empty()) {
    out->colour.assign(3 * pixels, 255);  // grey 1, as the SSDO's indirect term without colour
  } else {
    out->colour.assign(real.colour.begin(), real.colour.end());
  }
  out->object_id.assign(pixels, 0);
  const light::Intrinsics& k = real.intrinsics;
  const float fx = static_cast<float>(k.fx), fy = static_cast<float>(k.fy);
  const float cx = static_cast<float>(k.cx), cy = static_cast<float>(k.cy);
  int x0 = w, y0 = h, x1 = 0, y1 = 0;
  float min_z = std::numeric_limits<float>::max();
  for (size_t i = 0; i < objects.size(); ++i) {
    const RasterObject& o = objects[i];
    const std::string what = "render::RasteriseObjects: objects[" + std::to_string(i) + "]";
    if (o.mesh == nullptr) throw RenderError(what + ": no mesh");
    const raytrace::Mesh& mesh = *o.mesh;
    if (mesh.normals.size() != mesh.positions.size()) {
      throw RenderError(what + ": the mesh needs one normal per vertex");
    }
    const bool coloured = mesh.colors.size() == mesh.positions.size();
    std::vector<Vec3> p(mesh.positions.size()), n(mesh.positions.size());
    for (size_t v = 0; v < p.size(); ++v) {
      p[v] = o.object_to_camera.Apply(mesh.positions[v]);
      n[v] = o.object_to_camera.ApplyDirection(mesh.normals[v]);
    }
    const uint16_t id = static_cast<uint16_t>(std::min<size_t>(i + 1, 65535));
    for (const auto& tri : mesh.triangles) {
      if (tri[0] >= p.size() || tri[1] >= p.size() || tri[2] >= p.size()) {
        throw RenderError(what + ": triangle index out of range");
      }
      const Vec3 a = p[tri[0]], b = p[tri[1]], c = p[tri[2]];
      if (a.z < 0.01f || b.z < 0.01f || c.z < 0.01f) continue;
      // Facing the camera: the geometric normal (b - a) x (c - a) points towards the origin.
      const Vec3 e1{b.x - a.x, b.y - a.y, b.z - a.z}, e2{c.x - a.x, c.y - a.y, c.z - a.z};
      const Vec3 g{e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x};
      if (o.cull_back_faces && g.x * a.x + g.y * a.y + g.z * a.z >= 0) continue;
      const float ua = fx * a.x / a.z + cx, va = fy * a.y / a.z + cy;
      const float ub = fx * b.x / b.z + cx, vb = fy * b.y / b.z + cy;
      const float uc = fx * c.x / c.z + cx, vc = fy * c.y / c.z + cy;
      const float area = (ub - ua) * (vc - va) - (vb - va) * (uc - ua);
      if (!(std::abs(area) > 1e-12f)) continue;
      const int bu0 = std::max(0, static_cast<int>(std::ceil(std::min({ua, ub, uc}))));
      const int bu1 = std::min(w - 1, static_cast<int>(std::floor(std::max({ua, ub, uc}))));
      const int bv0 = std::max(0, static_cast<int>(std::ceil(std::min({va, vb, vc}))));
      const int bv1 = std::min(h - 1, static_cast<int>(std::floor(std::max({va, vb, vc}))));
      const float inv_area = 1.0f / area;
      const float iza = 1 / a.z, izb = 1 / b.z, izc = 1 / c.z;
      for (int v = bv0; v <= bv1; ++v) {
        for (int u = bu0; u <= bu1; ++u) {
          // Barycentrics of the pixel centre (screen space), then perspective-correct.
          const float wa = ((ub - static_cast<float>(u)) * (vc - static_cast<float>(v)) -
                            (vb - static_cast<float>(v)) * (uc - static_cast<float>(u))) *
                           inv_area;
          const float wb = ((uc - static_cast<float>(u)) * (va - static_cast<float>(v)) -
                            (vc - static_cast<float>(v)) * (ua - static_cast<float>(u))) *
                           inv_area;
          const float wc = 1 - wa - wb;
          if (wa < 0 || wb < 0 || wc < 0) continue;
          const float iz = wa * iza + wb * izb + wc * izc;
          const float z = 1 / iz;
          const size_t q = static_cast<size_t>(v) * w + u;
          const float zr = out->depth[q];
          if (zr > 0 && !(z < zr)) continue;
          const float pa = wa * iza * z, pb = wb * izb * z, pc = wc * izc * z;
          const Vec3 na = n[tri[0]], nb = n[tri[1]], nc = n[tri[2]];
          float nn[3] = {pa * na.x + pb * nb.x + pc * nc.x, pa * na.y + pb * nb.y + pc * nc.y,
                         pa * na.z + pb * nb.z + pc * nc.z};
          const float len = std::sqrt(nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2]);
          if (!(len > 0)) continue;
          // Facing the camera (the G_r convention): n . (pixel ray) < 0.
          const float ray = nn[0] * (u - cx) / fx + nn[1] * (v - cy) / fy + nn[2];
          const float sign = ray > 0 ? -1.0f : 1.0f;
          out->depth[q] = z;
          for (int j = 0; j < 3; ++j) out->normals[3 * q + j] = sign * nn[j] / len;
          Vec3 albedo = o.albedo;
          if (coloured) {
            const Vec3 ca = mesh.colors[tri[0]], cb = mesh.colors[tri[1]], cc = mesh.colors[tri[2]];
            albedo = {albedo.x * (pa * ca.x + pb * cb.x + pc * cc.x),
                      albedo.y * (pa * ca.y + pb * cb.y + pc * cc.y),
                      albedo.z * (pa * ca.z + pb * cb.z + pc * cc.z)};
          }
          out->colour[3 * q] = raytrace::LinearToSrgb8(albedo.x);
          out->colour[3 * q + 1] = raytrace::LinearToSrgb8(albedo.y);
          out->colour[3 * q + 2] = raytrace::LinearToSrgb8(albedo.z);
          out->object_id[q] = id;
        }
      }
    }
  }
  // The footprint of what is visible at the end (a later object may hide an earlier one).
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const size_t q = static_cast<size_t>(v) * w + u;
      if (out->object_id[q] == 0) continue;
      x0 = std::min(x0, u), x1 = std::max(x1, u + 1);
      y0 = std::min(y0, v), y1 = std::max(y1, v + 1);
      min_z = std::min(min_z, out->depth[q]);
    }
  }
  if (x1 > x0) {
    out->footprint = {x0, y0, x1, y1};
    out->min_virtual_depth = min_z;
  } else {
    out->footprint = {};
    out->min_virtual_depth = 0;
  }
}

void RasteriseHead(const raytrace::Mesh& head, const raytrace::Transform& face_to_camera,
                   const light::Intrinsics& k, int width, int height,
                   std::span<const uint8_t> camera_rgb, VirtualGeometry* out) {
  if (width < 1 || width > 8192 || height < 1 || height > 8192) {
    throw RenderError("render::RasteriseHead: size " + std::to_string(width) + "x" +
                      std::to_string(height) + " outside 1..8192");
  }
  const size_t pixels = static_cast<size_t>(width) * height;
  if (!camera_rgb.empty() && camera_rgb.size() != 3 * pixels) {
    throw RenderError("render::RasteriseHead: camera image of " +
                      std::to_string(camera_rgb.size()) + " bytes, expected " +
                      std::to_string(3 * pixels) + " (" + std::to_string(width) + "x" +
                      std::to_string(height) + " rgb8)");
  }
  // An empty G_r (no surface anywhere), then the head as the only "object".
  const std::vector<float> empty_depth(pixels, 0), empty_normals(3 * pixels, 0);
  const light::GeometryView empty{width, height, k, empty_depth, empty_normals, {}};
  const RasterObject o{&head, face_to_camera, {1, 1, 1}, false};
  try {
    RasteriseObjects(empty, {&o, 1}, out);
  } catch (const RenderError& e) {
    throw RenderError(std::string("render::RasteriseHead: ") + e.what());
  }
  for (size_t q = 0; q < pixels; ++q) {
    if (out->object_id[q] != 0 && !camera_rgb.empty()) {
      for (int j = 0; j < 3; ++j) out->colour[3 * q + j] = camera_rgb[3 * q + j];
    }
    out->object_id[q] = 0;
  }
  out->footprint = {};
  out->min_virtual_depth = 0;
}

light::PixelRect DifferentialWindow(const VirtualGeometry& g, const light::Intrinsics& k,
                                    const light::TransferOptions& options) {
  if (g.footprint.empty()) return {};
  const double r = options.radius_m;
  // A virtual surface s occludes a sample y = x + omega r' (r' <= r) only when it is in front of
  // y, so x lies deeper than the nearest virtual depth minus r (kept beyond r: a finite bound).
  const double zx = std::max<double>(g.min_virtual_depth - r, 1.2 * r);
  // |y - x| <= r seen from depth zx, magnified towards the image corners (1 + tan^2).
  const double tx = std::max(k.cx, g.width - 1 - k.cx) / k.fx;
  const double ty = std::max(k.cy, g.height - 1 - k.cy) / k.fy;
  const double reach =
      std::max(k.fx, k.fy) * r / std::sqrt(zx * zx - r * r) * (1 + tx * tx + ty * ty);
  const int d = static_cast<int>(std::ceil(std::min(reach, 1e5))) + 1;
  return {std::max(0, g.footprint.x0 - d), std::max(0, g.footprint.y0 - d),
          std::min(g.width, g.footprint.x1 + d), std::min(g.height, g.footprint.y1 + d)};
}

DifferentialRenderer::DifferentialRenderer(const DifferentialOptions& options) : options_(options) {
  if (options.step < 1) {
    throw RenderError("differential: step must be >= 1, got " + std::to_string(options.step));
  }
  if (!(options.key > 0)) throw RenderError("differential: key must be > 0");
  if (options.average_step < 1) throw RenderError("differential: average_step must be >= 1");
  if (options.smooth_radius < 0) throw RenderError("differential: smooth_radius must be >= 0");
  if (options.sun_shadow && options.tone != DifferentialTone::kRatio) {
    throw RenderError(
        "differential: sun_shadow needs tone ratio (the crisp shadow divides R'_d by "
        "R_d)");
  }
  if (options.sun_map_size < 16 || options.sun_map_size > 4096) {
    throw RenderError("differential: sun_map_size must be in 16..4096, got " +
                      std::to_string(options.sun_map_size));
  }
  if (!(options.sun_bias_m >= 0)) throw RenderError("differential: sun_bias_m must be >= 0");
  light::TransferOptions t = options.transfer;
  t.subsample = 1;
  computer_ = std::make_unique<light::TransferComputer>(t);
}

DifferentialRenderer::~DifferentialRenderer() = default;

void DifferentialRenderer::Compute(const DifferentialFrame& f, DifferentialResult* out) {
  const auto t0 = Clock::now();
  light::ValidateGeometryView(f.real, "render::DifferentialRenderer::Compute");
  const VirtualGeometry* gv = f.with_virtual;
  const int w = f.real.width, h = f.real.height;
  const size_t pixels = static_cast<size_t>(w) * h;
  if (gv == nullptr || gv->width != w || gv->height != h || gv->depth.size() != pixels ||
      gv->object_id.size() != pixels) {
    throw RenderError("render::DifferentialRenderer::Compute: with_virtual must be G_r' of the " +
                      std::to_string(w) + "x" + std::to_string(h) + " G_r (RasteriseObjects)");
  }
  if (!f.camera_rgb.empty() && f.camera_rgb.size() != 3 * pixels) {
    throw RenderError("render::DifferentialRenderer::Compute: camera image has " +
                      std::to_string(f.camera_rgb.size()) + " bytes, expected 3 x " +
                      std::to_string(w) + "x" + std::to_string(h));
  }
  *out = DifferentialResult{};
  const light::PixelRect win = DifferentialWindow(*gv, f.real.intrinsics, options_.transfer);
  // The crisp shadow of the light's directional part (sun_shadow): its light L_sun and every real
  // pixel's visibility V along d through the objects.
  ShLightRgb sun_light;
  bool sun = false;
  light::PixelRect shadow_rect;  // the pixels with V < 1 (empty: none)
  if (options_.sun_shadow && !f.objects.empty()) {
    const auto& dd = f.dominant.direction;
    Vec3 d{dd[0], dd[1], dd[2]};
    if (Dot(d, d) > 0.25f) {
      d = Normalize(d);
      sun_light = SunPart(f.light, d, &out->sun_amplitude);
      sun = *std::max_element(out->sun_amplitude.begin(), out->sun_amplitude.end()) > 0;
    }
    if (sun) {
      for (const RasterObject& o : f.objects) {
        if (o.mesh == nullptr)
          throw RenderError("render::DifferentialRenderer::Compute: null mesh");
      }
      SunMap map;
      map.d = d;
      map.Build(f.objects, options_.sun_map_size, &sun_map_);
      const float bias = options_.sun_bias_m + 2 * map.texel;
      sun_visibility_.assign(pixels, 1.0f);
      // V of real pixel (u, v) facing d; 1 elsewhere.
      auto visibility = [&](int u, int v) {
        const size_t p = static_cast<size_t>(v) * w + u;
        const float z = f.real.depth[p];
        if (gv->object_id[p] != 0 || !(z > 0)) return 1.0f;
        const float* n = &f.real.normals[3 * p];
        if (n[0] * d.x + n[1] * d.y + n[2] * d.z <= 0) return 1.0f;  // the sun is behind it
        float x[3];
        f.real.intrinsics.BackProject(u, v, z, x);
        return map.Visibility({x[0], x[1], x[2]}, bias);
      };
      // Every 2nd pixel finds the shadow's bounding box (dilated by 2), then every pixel in it.
      int x0 = w, y0 = h, x1 = -1, y1 = -1;
      for (int v = 0; v < h; v += 2) {
        for (int u = 0; u < w; u += 2) {
          if (visibility(u, v) >= 1) continue;
          x0 = std::min(x0, u), x1 = std::max(x1, u), y0 = std::min(y0, v), y1 = std::max(y1, v);
        }
      }
      if (x1 >= 0) {
        x0 = std::max(0, x0 - 2), y0 = std::max(0, y0 - 2);
        x1 = std::min(w - 1, x1 + 2), y1 = std::min(h - 1, y1 + 2);
        const int bx0 = x0, by0 = y0, bx1 = x1, by1 = y1;
        x0 = w, y0 = h, x1 = -1, y1 = -1;
        for (int v = by0; v <= by1; ++v) {
          for (int u = bx0; u <= bx1; ++u) {
            const float vis = visibility(u, v);
            if (vis >= 1) continue;
            sun_visibility_[static_cast<size_t>(v) * w + u] = vis;
            ++out->sun_shadow_pixels;
            x0 = std::min(x0, u), x1 = std::max(x1, u), y0 = std::min(y0, v), y1 = std::max(y1, v);
          }
        }
      }
      if (out->sun_shadow_pixels > 0) shadow_rect = {x0, y0, x1 + 1, y1 + 1};
      sun = out->sun_shadow_pixels > 0;
    }
  }
  if (win.empty() && !sun) {
    out->ms_total = MsSince(t0);
    return;
  }
  std::vector<float> sun_ratio;  // the window's T L_sun / T L per pixel (3 floats), with sun
  if (!win.empty()) {
    // G_r with the same reflector colours as G_r' on its real pixels (grey 1 without colour), so
    // that R_i and R'_i differ only by the virtual objects.
    light::GeometryView real = f.real;
    if (real.colour.empty()) {
      real_colour_.assign(3 * pixels, 255);
      real.colour = real_colour_;
    }
    const light::GeometryView with = gv->View(f.real.intrinsics);
    const bool indirect = options_.indirect && f.dominant.intensity > 0;
    const light::DominantLight* dominant = indirect ? &f.dominant : nullptr;
    const int step = options_.step;
    const auto t_transfer = Clock::now();
    // Per sample, whether a virtual pixel is within its own reach (the window's bound at the
    // sample's depth and direction): only those can differ, the others are skipped in both buffers.
    const int mw = (win.width() + step - 1) / step, mh = (win.height() + step - 1) / step;
    mask_.assign(static_cast<size_t>(mw) * mh, 0);
    {
      const light::Intrinsics& k = f.real.intrinsics;
      const double r = options_.transfer.radius_m;
      const light::PixelRect& fp = gv->footprint;
      const double z_near = gv->min_virtual_depth - r;
      for (int j = 0; j < mh; ++j) {
        for (int i = 0; i < mw; ++i) {
          const int u = std::min(win.x0 + i * step + step / 2, w - 1);
          const int v = std::min(win.y0 + j * step + step / 2, h - 1);
          const size_t p = static_cast<size_t>(v) * w + u;
          const float z = f.real.depth[p];
          if (!(z > 0) || gv->object_id[p] != 0 || z <= z_near) continue;
          const double tu = (u - k.cx) / k.fx, tv = (v - k.cy) / k.fy;
          const double zz = std::max<double>(z, 1.2 * r);
          const double reach = std::max(k.fx, k.fy) * r / std::sqrt(zz * zz - r * r) *
                                   (1 + tu * tu + tv * tv) * 1.1 +
                               step + 1;
          const double du = std::max({0, fp.x0 - u, u - (fp.x1 - 1)});
          const double dv = std::max({0, fp.y0 - v, v - (fp.y1 - 1)});
          mask_[static_cast<size_t>(j) * mw + i] = du * du + dv * dv <= reach * reach;
        }
      }
    }
    computer_->ComputeRegion(real, {}, dominant, win, step, &real_, mask_);
    computer_->ComputeRegion(with, {}, dominant, win, step, &with_, mask_);
    float avg_real = 0, avg_with = 0;
    if (options_.tone == DifferentialTone::kAverageKey) {
      // The per-buffer key of Gruber §5.4 (Reinhard 2002 eq. 1) over the whole image, sparsely.
      light::TransferResult sparse;
      const light::PixelRect all{0, 0, w, h};
      computer_->ComputeRegion(real, {}, nullptr, all, options_.average_step, &sparse);
      avg_real = LogAverage(sparse, f.light);
      computer_->ComputeRegion(with, {}, nullptr, all, options_.average_step, &sparse);
      avg_with = LogAverage(sparse, f.light);
    }
    if (options_.virtual_occlusion || (options_.virtual_bounce && indirect)) {
      // The objects' own pixels: the real scene's share of their occlusion and bounce light.
      // At every step-th pixel of the footprint (as the window), each virtual pixel taking its
      // nearest sample of the same object.
      const light::PixelRect& fp = gv->footprint;
      const int vw = (fp.width() + step - 1) / step, vh = (fp.height() + step - 1) / step;
      auto sample_pixel = [&](int i, int j) {
        return static_cast<size_t>(std::min(fp.y0 + j * step + step / 2, h - 1)) * w +
               std::min(fp.x0 + i * step + step / 2, w - 1);
      };
      virtual_mask_.assign(static_cast<size_t>(vw) * vh, 0);
      virtual_depth_.assign(pixels, 0.0f);
      for (int y = fp.y0; y < fp.y1; ++y) {
        for (int x = fp.x0; x < fp.x1; ++x) {
          const size_t p = static_cast<size_t>(y) * w + x;
          if (gv->object_id[p] != 0) virtual_depth_[p] = gv->depth[p];
        }
      }
      for (int j = 0; j < vh; ++j) {
        for (int i = 0; i < vw; ++i) {
          virtual_mask_[static_cast<size_t>(j) * vw + i] = gv->object_id[sample_pixel(i, j)] != 0;
        }
      }
      light::GeometryView only = with;
      only.depth = virtual_depth_;
      computer_->ComputeRegion(with, {}, dominant, fp, step, &virtual_with_, virtual_mask_);
      computer_->ComputeRegion(only, {}, dominant, fp, step, &virtual_only_, virtual_mask_);
      const size_t vcc = static_cast<size_t>(virtual_with_.coefficient_count);
      std::vector<float> per_sample(6 * virtual_mask_.size());
      for (size_t q = 0; q < virtual_mask_.size(); ++q) {
        float* o = &per_sample[6 * q];
        o[0] = o[1] = o[2] = 1;
        o[3] = o[4] = o[5] = 0;
        if (!virtual_mask_[q] || !virtual_with_.valid[q]) continue;
        const auto rv = ShadeTransfer({&virtual_with_.transfer[q * vcc], vcc}, f.light);
        const auto ro = ShadeTransfer({&virtual_only_.transfer[q * vcc], vcc}, f.light);
        for (int c = 0; c < 3; ++c) {
          if (options_.virtual_occlusion && ro[c] > 1e-4f)
            o[c] = std::clamp(rv[c] / ro[c], 0.0f, 1.0f);
          if (indirect && options_.virtual_bounce) {
            o[3 + c] = std::max(
                0.0f, virtual_with_.indirect[3 * q + c] - virtual_only_.indirect[3 * q + c]);
          }
        }
      }
      const size_t n = static_cast<size_t>(fp.width()) * fp.height();
      out->virtual_rect = fp;
      out->virtual_modulation.assign(3 * n, 1.0f);
      out->virtual_indirect.assign(3 * n, 0.0f);
      for (int y = fp.y0; y < fp.y1; ++y) {
        for (int x = fp.x0; x < fp.x1; ++x) {
          const size_t p = static_cast<size_t>(y) * w + x;
          if (gv->object_id[p] == 0) continue;
          const int i = std::min((x - fp.x0) / step, vw - 1),
                    j = std::min((y - fp.y0) / step, vh - 1);
          const size_t q = static_cast<size_t>(j) * vw + i;
          if (gv->object_id[sample_pixel(i, j)] != gv->object_id[p]) continue;
          const size_t r = static_cast<size_t>(y - fp.y0) * fp.width() + (x - fp.x0);
          std::copy_n(&per_sample[6 * q], 3, &out->virtual_modulation[3 * r]);
          std::copy_n(&per_sample[6 * q + 3], 3, &out->virtual_indirect[3 * r]);
        }
      }
    }
    out->ms_transfer = MsSince(t_transfer);
    out->average_real = avg_real;
    out->average_with_virtual = avg_with;

    const ToneMapping& tone = f.camera_tone;
    auto tone_real = [&](float x) {
      if (options_.tone == DifferentialTone::kFixed) return tone.Apply(x);
      const float s = options_.key * std::max(0.0f, x) / avg_real;
      return s / (1 + s);
    };
    auto tone_with = [&](float x) {
      if (options_.tone == DifferentialTone::kFixed) return tone.Apply(x);
      const float s = options_.key * std::max(0.0f, x) / avg_with;
      return s / (1 + s);
    };
    // Per sample: the eq. 13 factor and the eq. 14-15 addition (6 floats).
    const int sw = real_.width, sh = real_.height;
    const size_t cc = static_cast<size_t>(real_.coefficient_count);
    // With sun: 3 more, T L_sun / T L of the real buffer.
    const int nch = sun ? 9 : 6;
    std::vector<float> sample(nch * static_cast<size_t>(sw) * sh);
    for (int j = 0; j < sh; ++j) {
      for (int i = 0; i < sw; ++i) {
        const size_t s = static_cast<size_t>(j) * sw + i;
        float* o = &sample[nch * s];
        o[0] = o[1] = o[2] = 1;
        o[3] = o[4] = o[5] = 0;
        if (sun) o[6] = o[7] = o[8] = 0;
        const int u = std::min(win.x0 + i * step + step / 2, w - 1);
        const int v = std::min(win.y0 + j * step + step / 2, h - 1);
        const size_t p = static_cast<size_t>(v) * w + u;
        if (gv->object_id[p] != 0 || !real_.valid[s] || !with_.valid[s]) continue;
        const float* tr = &real_.transfer[s * cc];
        const float* tw = &with_.transfer[s * cc];
        const bool direct_differs = !std::equal(tr, tr + cc, tw);
        const bool bounce_differs =
            indirect &&
            !std::equal(&real_.indirect[3 * s], &real_.indirect[3 * s] + 3, &with_.indirect[3 * s]);
        std::array<float, 3> sd{0, 0, 0};  // T L_sun
        if (sun) {
          const auto rd = ShadeTransfer({tr, cc}, f.light);
          sd = ShadeTransfer({tr, cc}, sun_light);
          for (int c = 0; c < 3; ++c) o[6 + c] = rd[c] > 1e-4f ? std::max(0.0f, sd[c]) / rd[c] : 0;
        }
        if (!direct_differs && !bounce_differs) continue;
        const auto rd = ShadeTransfer({tr, cc}, f.light);
        const auto rv = ShadeTransfer({tw, cc}, f.light);
        if (direct_differs && sun) {
          // The sun's part with the real buffer's transfer here; the objects' V is applied per
          // pixel.
          const auto sv = ShadeTransfer({tw, cc}, sun_light);
          for (int c = 0; c < 3; ++c) {
            o[c] = rd[c] > 1e-4f ? std::clamp((rv[c] - sv[c] + sd[c]) / rd[c], 0.0f, 2.0f) : 1.0f;
          }
        } else if (direct_differs && options_.tone == DifferentialTone::kRatio) {
          for (int c = 0; c < 3; ++c) {
            o[c] = rd[c] > 1e-4f ? std::clamp(rv[c] / rd[c], 0.0f, 2.0f) : 1.0f;
          }
        } else if (direct_differs) {
          for (int c = 0; c < 3; ++c) {
            o[c] = std::max(0.0f, 1 + tone_with(rv[c]) - tone_real(rd[c]));  // eq. 13
          }
        }
        if (bounce_differs) {
          // Eq. 14 adds R'_i where it differs from R_i; the camera already shows the real-only
          // bounce R_i, so only the virtual objects' part, R'_i - R_i (>= 0), is added, times the
          // pixel's albedo I_c / T(R_d) and the camera's exposure.
          for (int c = 0; c < 3; ++c) {
            const float delta =
                std::max(0.0f, with_.indirect[3 * s + c] - real_.indirect[3 * s + c]);
            float albedo = 1;
            if (!f.camera_rgb.empty()) {
              const float lit = std::max(tone.Apply(rd[c]), 0.02f);
              albedo = std::min(1.0f, light::SrgbToLinear(f.camera_rgb[3 * p + c]) / lit);
            }
            o[3 + c] = delta * albedo * tone.exposure;
          }
        }
      }
    }
    if (options_.smooth_radius > 0) {
      // Edge-aware box, rows then columns, over the real samples of similar depth; a neighbourhood
      // of unchanged samples (1, 0) stays exactly unchanged (a mean of equal values).
      std::vector<float> depth(static_cast<size_t>(sw) * sh, 0.0f);
      for (int j = 0; j < sh; ++j) {
        for (int i = 0; i < sw; ++i) {
          const int u = std::min(win.x0 + i * step + step / 2, w - 1);
          const int v = std::min(win.y0 + j * step + step / 2, h - 1);
          const size_t p = static_cast<size_t>(v) * w + u;
          const size_t s = static_cast<size_t>(j) * sw + i;
          // Skipped samples (mask 0) are unchanged and take no part.
          if (gv->object_id[p] == 0 && real_.valid[s] && mask_[s]) depth[s] = f.real.depth[p];
        }
      }
      std::vector<float> tmp(sample.size());
      const int r = options_.smooth_radius;
      auto pass = [&](const std::vector<float>& src, std::vector<float>& dst, bool rows) {
        const int lines = rows ? sh : sw, length = rows ? sw : sh;
        for (int line = 0; line < lines; ++line) {
          for (int i = 0; i < length; ++i) {
            const size_t s =
                rows ? static_cast<size_t>(line) * sw + i : static_cast<size_t>(i) * sw + line;
            std::copy_n(&src[nch * s], nch, &dst[nch * s]);
            const float z = depth[s];
            if (!(z > 0)) continue;
            float acc[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
            int n = 0;
            for (int k = std::max(0, i - r); k <= std::min(length - 1, i + r); ++k) {
              const size_t t =
                  rows ? static_cast<size_t>(line) * sw + k : static_cast<size_t>(k) * sw + line;
              if (!(depth[t] > 0) || std::abs(depth[t] - z) > 0.03f * z) continue;
              for (int c = 0; c < nch; ++c) acc[c] += src[nch * t + c];
              ++n;
            }
            for (int c = 0; c < nch; ++c) dst[nch * s + c] = acc[c] / n;
          }
        }
      };
      pass(sample, tmp, true);
      pass(tmp, sample, false);
    }
    // Full resolution on the window (bilinear between samples when step > 1; equal taps copied, so
    // an unchanged neighbourhood stays exactly 1 and 0).
    out->window = win;
    const size_t wp = static_cast<size_t>(win.width()) * win.height();
    out->factor.assign(3 * wp, 1.0f);
    out->indirect.assign(3 * wp, 0.0f);
    if (sun) sun_ratio.assign(3 * wp, 0.0f);
    for (int y = win.y0; y < win.y1; ++y) {
      for (int x = win.x0; x < win.x1; ++x) {
        const size_t q = static_cast<size_t>(y - win.y0) * win.width() + (x - win.x0);
        if (gv->object_id[static_cast<size_t>(y) * w + x] != 0) continue;
        const float* vals[4];
        float wt[4];
        if (step == 1) {
          vals[0] = &sample[nch * q];
          wt[0] = 1;
          vals[1] = vals[2] = vals[3] = vals[0];
          wt[1] = wt[2] = wt[3] = 0;
        } else {
          const float fx = static_cast<float>(x - win.x0 - step / 2) / step;
          const float fy = static_cast<float>(y - win.y0 - step / 2) / step;
          const int i0 = std::clamp(static_cast<int>(std::floor(fx)), 0, sw - 1);
          const int j0 = std::clamp(static_cast<int>(std::floor(fy)), 0, sh - 1);
          const int i1 = std::min(i0 + 1, sw - 1), j1 = std::min(j0 + 1, sh - 1);
          const float ax = std::clamp(fx - i0, 0.0f, 1.0f), ay = std::clamp(fy - j0, 0.0f, 1.0f);
          vals[0] = &sample[nch * (static_cast<size_t>(j0) * sw + i0)];
          vals[1] = &sample[nch * (static_cast<size_t>(j0) * sw + i1)];
          vals[2] = &sample[nch * (static_cast<size_t>(j1) * sw + i0)];
          vals[3] = &sample[nch * (static_cast<size_t>(j1) * sw + i1)];
          wt[0] = (1 - ax) * (1 - ay), wt[1] = ax * (1 - ay), wt[2] = (1 - ax) * ay,
          wt[3] = ax * ay;
        }
        bool changed = false;
        for (int c = 0; c < nch; ++c) {
          const float v0 = vals[0][c];
          float value = v0;
          if (vals[1][c] != v0 || vals[2][c] != v0 || vals[3][c] != v0) {
            value = wt[0] * v0 + wt[1] * vals[1][c] + wt[2] * vals[2][c] + wt[3] * vals[3][c];
          }
          if (c < 3) {
            out->factor[3 * q + c] = value;
          } else if (c < 6) {
            out->indirect[3 * q + c - 3] = value;
          } else {
            sun_ratio[3 * q + c - 6] = value;
            continue;
          }
          changed |= c < 3 ? value != 1 : value != 0;
        }
        out->changed_pixels += changed;
        out->min_factor = std::min(out->min_factor, out->factor[3 * q]);
      }
    }
  }  // !win.empty()
  if (sun) {
    // The crisp shadow on the union of the window and the shadowed pixels: factor - (1 - V) b,
    // b = T L_sun / T L (the window's SSDO where it has it, else the unoccluded transfer).
    light::PixelRect u = shadow_rect;
    if (!win.empty()) {
      u = {std::min(win.x0, u.x0), std::min(win.y0, u.y0), std::max(win.x1, u.x1),
           std::max(win.y1, u.y1)};
    }
    const size_t up = static_cast<size_t>(u.width()) * u.height();
    std::vector<float> factor(3 * up, 1.0f), indirect_u(3 * up, 0.0f);
    auto in_win = [&](int x, int y) {
      return x >= win.x0 && x < win.x1 && y >= win.y0 && y < win.y1;
    };
    for (int y = u.y0; y < u.y1; ++y) {
      for (int x = u.x0; x < u.x1; ++x) {
        const size_t q = static_cast<size_t>(y - u.y0) * u.width() + (x - u.x0);
        const size_t p = static_cast<size_t>(y) * w + x;
        const size_t qw =
            in_win(x, y) ? static_cast<size_t>(y - win.y0) * win.width() + (x - win.x0) : SIZE_MAX;
        if (qw != SIZE_MAX) {
          std::copy_n(&out->factor[3 * qw], 3, &factor[3 * q]);
          std::copy_n(&out->indirect[3 * qw], 3, &indirect_u[3 * q]);
        }
        const float vis = sun_visibility_[p];
        if (vis >= 1) continue;
        std::array<float, 3> b{0, 0, 0};
        if (qw != SIZE_MAX) std::copy_n(&sun_ratio[3 * qw], 3, b.begin());
        if (b[0] <= 0 && b[1] <= 0 && b[2] <= 0) {
          const Vec3 n{f.real.normals[3 * p], f.real.normals[3 * p + 1], f.real.normals[3 * p + 2]};
          const auto r = ShadeUnoccluded(f.light, n);
          const auto sd = ShadeUnoccluded(sun_light, n);
          for (int c = 0; c < 3; ++c) b[c] = r[c] > 1e-4f ? std::max(0.0f, sd[c]) / r[c] : 0;
        }
        for (int c = 0; c < 3; ++c) {
          factor[3 * q + c] = std::clamp(factor[3 * q + c] - (1 - vis) * b[c], 0.0f, 2.0f);
        }
      }
    }
    out->window = u;
    out->factor = std::move(factor);
    out->indirect = std::move(indirect_u);
    out->changed_pixels = 0;
    out->min_factor = 1;
    for (size_t q = 0; q < up; ++q) {
      bool changed = false;
      for (int c = 0; c < 3; ++c) {
        changed |= out->factor[3 * q + c] != 1 || out->indirect[3 * q + c] != 0;
      }
      out->changed_pixels += changed;
      out->min_factor = std::min(out->min_factor, out->factor[3 * q]);
    }
  }
  out->ms_total = MsSince(t0);
}

void ApplyDifferential(const DifferentialResult& r, int width, int height,
                       std::span<uint8_t> camera_rgb) {
  if (width < 1 || height < 1 || camera_rgb.size() != static_cast<size_t>(width) * height * 3) {
    throw RenderError("render::ApplyDifferential: camera image has " +
                      std::to_string(camera_rgb.size()) + " bytes, expected 3 x " +
                      std::to_string(width) + "x" + std::to_string(height));
  }
  const light::PixelRect& win = r.window;
  if (win.empty()) return;
  const size_t wp = static_cast<size_t>(win.width()) * win.height();
  if (win.x0 < 0 || win.y0 < 0 || win.x1 > width || win.y1 > height || r.factor.size() != 3 * wp ||
      r.indirect.size() != 3 * wp) {
    throw RenderError("render::ApplyDifferential: the result's window does not fit the image");
  }
  for (int y = win.y0; y < win.y1; ++y) {
    for (int x = win.x0; x < win.x1; ++x) {
      const size_t q = static_cast<size_t>(y - win.y0) * win.width() + (x - win.x0);
      const float* f = &r.factor[3 * q];
      const float* a = &r.indirect[3 * q];
      if (f[0] == 1 && f[1] == 1 && f[2] == 1 && a[0] == 0 && a[1] == 0 && a[2] == 0) continue;
      uint8_t* c = &camera_rgb[3 * (static_cast<size_t>(y) * width + x)];
      for (int k = 0; k < 3; ++k) {
        c[k] = raytrace::LinearToSrgb8(light::SrgbToLinear(c[k]) * f[k] + a[k]);  // eq. 13, 15
      }
    }
  }
}

raytrace::Vec3 GroupCentre(std::span<const raytrace::Mesh* const> meshes) {
  if (meshes.empty()) throw RenderError("render::GroupCentre: no meshes");
  Vec3 lo{1e30f, 1e30f, 1e30f}, hi{-1e30f, -1e30f, -1e30f};
  for (const raytrace::Mesh* m : meshes) {
    for (const Vec3& p : m->positions) {
      lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
      hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    }
  }
  if (!(lo.x <= hi.x)) throw RenderError("render::GroupCentre: the meshes have no vertices");
  return {(lo.x + hi.x) / 2, (lo.y + hi.y) / 2, (lo.z + hi.z) / 2};
}

std::optional<raytrace::Transform> PlaceOnSurface(const light::GeometryView& g, double u, double v,
                                                  const raytrace::Transform& camera_to_world,
                                                  std::span<const raytrace::Mesh* const> meshes) {
  light::ValidateGeometryView(g, "render::PlaceOnSurface");
  if (!(u > -0.5 && v > -0.5 && u < g.width - 0.5 && v < g.height - 0.5)) {
    char pixel[64];
    std::snprintf(pixel, sizeof(pixel), "[%g, %g]", u, v);
    throw RenderError("object_pixel " + std::string(pixel) + " is outside the " +
                      std::to_string(g.width) + "x" + std::to_string(g.height) + " image");
  }
  if (meshes.empty()) throw RenderError("render::PlaceOnSurface: no meshes to place");
  const int pu = static_cast<int>(std::lround(u)), pv = static_cast<int>(std::lround(v));
  int best = -1;
  double best_d2 = 1e30;
  double n[3] = {0, 0, 0};
  for (int dv = -2; dv <= 2; ++dv) {
    for (int du = -2; du <= 2; ++du) {
      const int x = pu + du, y = pv + dv;
      if (x < 0 || y < 0 || x >= g.width || y >= g.height) continue;
      const size_t q = static_cast<size_t>(y) * g.width + x;
      const float* nq = &g.normals[3 * q];
      if (!(g.depth[q] > 0) || (nq[0] == 0 && nq[1] == 0 && nq[2] == 0)) continue;
      for (int c = 0; c < 3; ++c) n[c] += nq[c];
      const double d2 = du * du + dv * dv;
      if (d2 < best_d2) best_d2 = d2, best = static_cast<int>(q);
    }
  }
  const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  if (best < 0 || !(len > 0)) return std::nullopt;
  float xc[3];
  g.intrinsics.BackProject(best % g.width, best / g.width, g.depth[best], xc);
  const Vec3 x = camera_to_world.Apply({xc[0], xc[1], xc[2]});
  const Vec3 nw = camera_to_world.ApplyDirection({static_cast<float>(n[0] / len),
                                                  static_cast<float>(n[1] / len),
                                                  static_cast<float>(n[2] / len)});
  const Vec3 c = GroupCentre(meshes);
  double h = 0;
  for (const raytrace::Mesh* m : meshes) {
    for (const Vec3& p : m->positions) {
      h = std::max(
          h, static_cast<double>((c.x - p.x) * nw.x + (c.y - p.y) * nw.y + (c.z - p.z) * nw.z));
    }
  }
  raytrace::Transform t;
  t.translation = {x.x + nw.x * h - c.x, x.y + nw.y * h - c.y, x.z + nw.z * h - c.z};
  return t;
}

}  // namespace probeless::render
