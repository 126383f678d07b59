// Depth preprocessing (KinectFusion, Newcombe et al. 2011, §3.1): millimetres -> metres, bilateral
// filter, a 3-level depth pyramid, and per-level vertex and normal maps in the camera frame
// (x right, y down, z forward).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "probeless/recon/math.h"
#include "probeless/recon/thread_pool.h"

namespace probeless::recon {

struct PreprocessOptions {
  float depth_min_m = 0.3f;     // depth below this is invalid, metres
  float depth_max_m = 4.0f;     // depth above this is invalid, metres
  int bilateral_radius = 2;     // filter window (2r+1)^2 pixels; 0 = no filter
  float sigma_space_px = 3.0f;  // spatial sigma, pixels
  float sigma_depth_m = 0.03f;  // range sigma, metres; also the pyramid's edge threshold (3 sigma)
  int levels = 3;               // tracked pyramid levels (1..4) from first_level on
  // The finest level that is filtered and gets vertex and normal maps; the levels below it hold
  // only the (range-checked, unfiltered) depth. 0 = full resolution, 1 = half (0..2).
  int first_level = 0;
};

// The preprocessed frame: per level l (0 = full resolution, first_level + levels in all) the depth
// (metres, 0 = invalid), and from first_level on the vertex map (camera frame, metres; z = 0 =
// invalid) and the normal map (unit, camera frame, pointing towards the camera; (0, 0, 0) =
// invalid); below first_level the vertex and normal maps are empty.
struct FramePyramid {
  DepthImage raw_depth;  // level 0 before the bilateral filter (range-checked), metres
  std::vector<Intrinsics> intrinsics;
  std::vector<DepthImage> depth;
  std::vector<Vec3Image> vertices;
  std::vector<Vec3Image> normals;
};

// Converts a depth16 image (millimetres, `stride_elements` uint16 per row, 0 = invalid) to metres
// with `metres_per_unit` (0.001 for depth16), invalidating values outside [min, max] metres.
// Throws ReconError for an empty image, a stride < width or a non-positive/non-finite scale.
void DepthFromUnits(const uint16_t* units, int width, int height, size_t stride_elements,
                    double metres_per_unit, float min_m, float max_m, DepthImage& out);

// Edge-preserving bilateral filter of `in` (metres, 0 = invalid stays invalid) into `out`.
void BilateralFilter(const DepthImage& in, const PreprocessOptions& options, DepthImage& out,
                     ThreadPool* pool);

// Vertex map of `depth` with `intrinsics` (camera frame).
void ComputeVertexMap(const DepthImage& depth, const Intrinsics& intrinsics, Vec3Image& out,
                      ThreadPool* pool);
// Normal map from central differences of the vertex map, oriented towards the camera; invalid
// where a neighbour is missing or the surface jumps by more than 10 cm.
void ComputeNormalMap(const Vec3Image& vertices, Vec3Image& out, ThreadPool* pool);

// The whole chain on a depth image in metres (raw_depth = `depth_m`). Throws ReconError for empty
// depth, a size that differs from the intrinsics, invalid intrinsics or options.
void Preprocess(const DepthImage& depth_m, const Intrinsics& intrinsics,
                const PreprocessOptions& options, FramePyramid& out, ThreadPool* pool);

}  // namespace probeless::recon
