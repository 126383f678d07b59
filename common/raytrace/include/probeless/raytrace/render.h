// Rendering a Scene through a pinhole camera into RGB-D frames with normals and object ids, and
// the ground-truth lighting seen at a point as SH coefficients.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "probeless/raytrace/geometry.h"
#include "probeless/raytrace/scene.h"

namespace probeless::raytrace {

// A pinhole camera without distortion: a point (X, Y, Z) of the camera frame (x right, y down,
// z forward, metres) projects to pixel u = fx X / Z + cx, v = fy Y / Z + cy, (0, 0) the centre of
// the top-left pixel (msgs::CameraInfo).
struct Camera {
  int width = 640;
  int height = 480;
  double fx = 525;
  double fy = 525;
  double cx = 319.5;
  double cy = 239.5;
  Transform camera_to_world;  // the camera pose (p_world = R p_camera + t)

  // Throws RaytraceError unless width, height >= 1 and fx, fy > 0.
  void Validate() const;
};

struct RenderOptions {
  bool shadows = true;          // occlusion rays towards directional and point lights
  bool diffuse_bounce = false;  // one diffuse bounce of direct light (Monte-Carlo)
  int bounce_samples = 4;       // cosine-weighted rays per pixel for the bounce (>= 1)
  uint64_t seed = 1;            // seeds the bounce sampling (with the frame index)
  uint64_t frame_index = 0;     // decorrelates the bounce noise between frames
  int rows_per_task = 8;        // image rows per ThreadPool task (>= 1)
  float ray_epsilon = 1e-4f;    // metres: offset of secondary ray origins along the normal
};

// One rendered frame; every image is width x height, row-major, top-left first.
struct Frame {
  int width = 0;
  int height = 0;
  std::vector<float> linear_rgb;     // 3 per pixel, linear radiance (1 = full scale), unclamped
  std::vector<uint8_t> srgb;         // 3 per pixel, sRGB-encoded clamp(linear_rgb) (msgs rgb8)
  std::vector<float> depth_m;        // z along the optical axis, metres; 0 = no hit
  std::vector<uint16_t> depth_mm;    // round(depth_m * 1000); 0 = no hit or beyond 65.535 m
  std::vector<float> normals;        // 3 per pixel, unit shading normal in the camera frame
                                     // (facing the camera); (0, 0, 0) = no hit
  std::vector<uint32_t> object_ids;  // the hit object's id; 0 = background
  std::vector<float> albedo;         // 3 per pixel, linear albedo of the first mesh surface seen
                                     // (SurfacePoint::albedo); (0, 0, 0) = none (background, or
                                     // PathTrace's area light seen directly)
  uint64_t rays = 0;                 // rays traced for this frame (primary, shadow, bounce)
};

// Renders `scene` (committed) from `camera`: primary rays as streams of image rows, direct light
// from directional and point lights (Lambert + optional Blinn-Phong, shadowed by occlusion rays
// when options.shadows), the environment's SH irradiance (unshadowed) and optionally one diffuse
// bounce. Background pixels get the environment radiance in their direction. Deterministic: the
// same inputs give byte-identical frames whatever the thread count. Throws RaytraceError for an
// invalid camera or options.
Frame Render(const Scene& scene, const Camera& camera, const RenderOptions& options,
             ThreadPool* pool = nullptr);

// sRGB encoding of one linear value (clamped to [0, 1]) to 0..255.
uint8_t LinearToSrgb8(float linear);
// Linear value of an sRGB-encoded 0..255 value.
float Srgb8ToLinear(uint8_t srgb);

// Distant incident lighting at `point` (world) as 9 SH coefficients (bands 0..2, msgs/sh_light.h
// convention, linear RGB) expressed in the frame whose axes are given by `frame_to_world` rotation
// (e.g. the camera rotation for camera-frame coefficients): the environment rotated into that
// frame, plus each enabled directional light as irradiance * Y(d) and each enabled point light as
// a directional light from its direction at `point` with irradiance intensity / r^2. Lights are
// not tested for occlusion. Also returns the dominant light (the enabled directional or point
// light of largest mean irradiance; direction (0, 0, 0) and 0 if none) in that frame.
struct LightingGroundTruth {
  std::array<Vec3, 9> sh{};
  Vec3 dominant_direction;
  float dominant_irradiance = 0;  // mean of R, G, B
};
LightingGroundTruth LightingAt(const Scene& scene, Vec3 point, const Mat3& frame_to_world);

// The 9 real SH basis values (bands 0..2, msgs/sh_light.h convention) at unit direction d.
std::array<float, 9> ShBasis9(Vec3 d);

}  // namespace probeless::raytrace
