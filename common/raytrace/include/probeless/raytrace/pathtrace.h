// Physically based rendering of a Scene: an unbiased path tracer (next-event estimation with
// multiple importance sampling, Russian roulette, Lambert + GGX), a virtual light probe that
// projects the traced incident radiance onto SH, and blackbody colours. docs/raytrace.md
// "Path tracing" has the conventions; the units are those of scene.h (linear RGB, 1 = full scale).
#pragma once

#include <array>
#include <cstdint>
#include <functional>

#include "probeless/raytrace/geometry.h"
#include "probeless/raytrace/render.h"
#include "probeless/raytrace/scene.h"

namespace probeless::raytrace {

struct PathTraceOptions {
  int samples_per_pixel = 64;  // paths per pixel (>= 1), jittered over the pixel (box filter)
  // Bounces after the first hit (>= 0): 0 = direct light only (lights by next-event estimation,
  // environment, area lights and emitters by the one BSDF ray after the first hit).
  int max_bounces = 3;
  int russian_roulette_after = 0;  // bounces before Russian roulette starts (>= 0)
  float exposure = 1;              // multiplies the radiance into Frame::linear_rgb and srgb (>= 0)
  uint64_t seed = 1;               // with frame_index, the only source of the random numbers
  uint64_t frame_index = 0;        // decorrelates the noise between frames
  int rows_per_task = 8;           // image rows per ThreadPool task (>= 1)
  float ray_epsilon = 1e-4f;       // metres: offset of secondary ray origins along the normal
  // Next-event estimation of every light at every vertex (one shadow ray each) instead of one
  // light chosen by its unshadowed contribution: less noise per path, more rays per path.
  bool all_lights = false;
  // Called from the calling thread, after each tile it renders and at the end, with the rows
  // finished so far (increasing, the last call (total_rows, total_rows)); may be null.
  std::function<void(int done_rows, int total_rows)> progress;

  // Throws RaytraceError naming the first invalid field, e.g.
  // "PathTraceOptions: samples_per_pixel must be >= 1, got 0".
  void Validate() const;
};

// Renders `scene` (committed) from `camera` with unbiased path tracing: next-event estimation of
// directional lights (delta, or discs of angular_radius sampled by solid angle), point lights and
// area lights (one light per vertex chosen by its unshadowed contribution, or all of them with
// options.all_lights), multiple importance
// sampling (power heuristic) for discs and area lights, the environment (SH radiance, clamped >= 0,
// shadowed: seen by rays that escape) and Material::emission reached by BSDF sampling, Russian
// roulette after options.russian_roulette_after bounces, Lambert + energy-conserving GGX.
// Fills the Frame as Render does: linear_rgb = exposure * radiance (mean over the paths), srgb,
// and depth_m, depth_mm, normals, object_ids from the ray through the pixel centre (an area light
// seen there gives its id, depth and facing normal); background pixels see the environment.
// Deterministic and correlated: the random numbers of pixel (x, y), sample s depend only on
// (seed, frame_index, x, y, s), never on the thread or other pixels, so the same scene with one
// extra object changes only the pixels whose paths (or their shadow rays) touch that object.
// Throws RaytraceError for an invalid camera, options or area light.
Frame PathTrace(const Scene& scene, const Camera& camera, const PathTraceOptions& options,
                ThreadPool* pool = nullptr);

// The incident radiance at `point` (world, metres) over the whole sphere projected onto 9 SH
// coefficients (bands 0..2, msgs/sh_light.h convention, world frame, linear RGB, times
// options.exposure), estimated from `directions` (>= 1) stratified directions (equal-area
// stratification of the sphere, jittered by (seed, frame_index, direction index)), each traced as
// a full path (occlusion, bounces, emitters, lights, environment): a virtual light probe. The
// geometry at `point` itself is not special: place it in free space. options.samples_per_pixel
// and rows_per_task are not used. Throws RaytraceError for directions < 1 or invalid options.
std::array<Vec3, 9> IncidentRadianceSh(const Scene& scene, Vec3 point, int directions,
                                       const PathTraceOptions& options, ThreadPool* pool = nullptr);

// Linear RGB (Rec. 709 primaries, D65 white) of a blackbody at `kelvin` in [1000, 40000],
// normalised to luminance (Y) 1; components outside the gamut are clamped to 0 before the
// normalisation. Throws RaytraceError outside that range.
Vec3 BlackbodyRgb(double kelvin);

}  // namespace probeless::raytrace
