// A truncated signed distance volume (Curless & Levoy 1996; KinectFusion, Newcombe et al. 2011)
// on the CPU: a dense grid stored as 8^3-voxel bricks, integrated only in the bricks touched by
// the current depth's truncation band (plus already-observed bricks the rays pass through, so
// free space is carved), and raycast with empty-space skipping: rays start and end at the depth
// range of the bricks near a surface that project to their 8 x 8-pixel tile, and skip bricks
// without any voxel near a surface (unobserved or pure free space), whole 4^3-brick cells when
// none of their bricks has one.
// The volume lives in the world frame (metres): voxel (i, j, k) has its centre at
// origin + (i + 0.5, j + 0.5, k + 0.5) * voxel_size.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "probeless/recon/math.h"
#include "probeless/recon/thread_pool.h"

namespace probeless::recon {

struct VolumeOptions {
  int resolution = 256;  // voxels per side, a multiple of 8 in [8, 1024]
  float size_m = 2.0f;   // side of the cube, metres (paper: 256^3 over 2 m)
  // World position of the cube's minimum corner, metres. The default puts a first camera at the
  // identity pose 0.5 m before the cube's near face, centred in x and 0.2 m below centre in y
  // (x in [-1, 1], y in [-1.2, 0.8], z in [0.5, 2.5]): a hand-held sensor's view of a room.
  Vec3f origin = {-1.0f, -1.2f, 0.5f};
  float truncation_m = 0.03f;  // truncation distance mu, metres (> one voxel)
  int max_weight = 64;         // running-average weight cap, 1..255 (lower = faster update)
  int mark_stride = 4;         // pixel stride when finding the bricks the band touches
  int carve_stride = 16;       // pixel stride of free-space carving rays; 0 = no carving

  // Throws ReconError naming the field for an out-of-range value.
  void Validate() const;
};

// One rendered view of the volume: depth along the view's z axis (metres, 0 = no surface), unit
// normals in the view frame pointing towards the viewer ((0, 0, 0) = none) and the surface points
// in the view frame (z = 0 = none). This is the paper's G_v = (D_v, N_v) (§4).
struct GeometryView {
  DepthImage depth;
  Vec3Image normals;
  Vec3Image points;
};

// An orthographic view: parallel rays along the view's +z axis from the plane z = 0 of the view
// frame; pixel (x, y) starts at view coordinates ((x - (width - 1) / 2) * pixel_size,
// (y - (height - 1) / 2) * pixel_size, 0).
struct OrthographicView {
  Pose view_to_world;      // view frame -> world (x right, y down, z along the rays)
  int width = 0;           // pixels
  int height = 0;          // pixels
  float pixel_size_m = 0;  // metres per pixel
};

// The auxiliary orthographic views of the paper's §5.1 for a camera pose: looking at the volume
// from the camera's left (rays along +x of the camera), right (rays along -x) and top (rays along
// +y, i.e. downwards in the image), each centred on the volume centre, `pixels` square, covering
// the whole volume, starting outside it.
struct AuxiliaryViews {
  OrthographicView left;
  OrthographicView right;
  OrthographicView top;
};

// A triangle mesh (world frame, metres): vertices with unit normals, triangles as vertex indices
// (counter-clockwise seen from the side the normals point to).
struct Mesh {
  std::vector<Vec3f> vertices;
  std::vector<Vec3f> normals;
  std::vector<uint32_t> indices;  // 3 per triangle
};

struct IntegrateStats {
  int bricks = 0;       // bricks integrated this call
  uint64_t voxels = 0;  // voxels updated
};

class TsdfVolume {
 public:
  // Allocates resolution^3 voxels (5 bytes each). Throws ReconError for invalid options.
  explicit TsdfVolume(const VolumeOptions& options);

  const VolumeOptions& options() const { return options_; }
  float voxel_size() const { return voxel_size_; }
  // Forgets every observation.
  void Reset();

  // Fuses `depth` (metres along z, 0 = invalid) seen with `intrinsics` from `camera_to_world`
  // (KinectFusion eq. 9-11: projective TSDF, running weighted average capped at max_weight).
  // Throws ReconError if the depth size differs from the intrinsics or they are invalid.
  IntegrateStats Integrate(const DepthImage& depth, const Intrinsics& intrinsics,
                           const Pose& camera_to_world, ThreadPool* pool);

  // Raycasts the zero crossing for every pixel of the perspective camera (G_v in the camera's
  // frame). Throws ReconError for invalid intrinsics.
  void Raycast(const Pose& camera_to_world, const Intrinsics& intrinsics, GeometryView& out,
               ThreadPool* pool) const;
  // Raycasts an orthographic view (depth = distance along the rays from the view plane). Throws
  // ReconError for a non-positive size or pixel size.
  void RaycastOrthographic(const OrthographicView& view, GeometryView& out, ThreadPool* pool) const;
  // The left/right/top auxiliary views (§5.1) for a camera at `camera_to_world`.
  AuxiliaryViews AuxiliaryViewsFor(const Pose& camera_to_world, int pixels) const;
  // An orthographic view looking along -`direction_world` (rays travel from the light towards
  // the scene; `direction_world` points towards the light), covering the volume. Throws
  // ReconError for a zero or non-finite direction.
  OrthographicView LightView(Vec3f direction_world, int pixels) const;

  // Trilinear TSDF value (in units of the truncation distance, [-1, 1]) at a world point; NaN
  // outside the volume or where any of the 8 voxels is unobserved.
  float TsdfAt(Vec3f world) const;
  // Surface normal at a world point from the TSDF gradient: central differences of the trilinear
  // TSDF at +-`step_voxels` voxels along each world axis (KinectFusion, Newcombe et al. 2011
  // §3.5's raycast normal, here at an arbitrary point), normalised; world frame, pointing out of
  // the surface (towards free space). False (and `normal` untouched) outside the volume, where a
  // sample is unobserved or the gradient vanishes.
  bool NormalAt(Vec3f world, float step_voxels, Vec3f* normal) const;
  // Whether the brick holding voxel (i, j, k) has been observed.
  bool BrickObserved(int i, int j, int k) const;
  int ObservedBricks() const;

  // The observed bricks, for a checkpoint of the map (FusionPipeline::Checkpoint): appends to
  // `out` their count (uint32) and, per brick in increasing order, its index (uint32, brick-major:
  // (bk * side + bj) * side + bi for side = resolution / 8), its 512 TSDF values (float, in units
  // of the truncation distance) and its 512 weights (uint8), in this machine's representation.
  void AppendObservedBricks(std::vector<std::byte>& out) const;
  // Replaces every observation by bricks in AppendObservedBricks' layout, read from `in` at
  // `*offset` (advanced past them), written by a volume with the same options. Throws ReconError
  // "<name>: ..." for truncated data, a brick index out of range or not increasing, a weight above
  // max_weight, a TSDF value outside [-1, 1] where the weight is > 0 or a weight-0 voxel that is
  // not unobserved; the volume is then empty.
  void ReadObservedBricks(std::span<const std::byte> in, size_t* offset, const std::string& name);

  // The zero level set of the observed voxels (marching cubes on each voxel cube, split into six
  // tetrahedra so no case tables are needed; normals from the TSDF gradient).
  Mesh ExtractMesh(ThreadPool* pool) const;

 private:
  friend struct VolumeAccess;
  size_t VoxelIndex(int i, int j, int k) const {
    const int b = ((k >> 3) * bricks_ + (j >> 3)) * bricks_ + (i >> 3);
    return (static_cast<size_t>(b) << 9) | ((k & 7) << 6) | ((j & 7) << 3) | (i & 7);
  }
  void March(Vec3f origin, Vec3f dir, float t_min, float t_max, float* t_hit, Vec3f* normal) const;
  // Recomputes coarse_ from surface_.
  void UpdateCoarse();

  VolumeOptions options_;
  int res_ = 0;
  int bricks_ = 0;  // bricks per side
  float voxel_size_ = 0;
  float inv_voxel_ = 0;
  std::vector<float> tsdf_;        // per voxel, brick-major; [-1, 1]
  std::vector<uint8_t> weight_;    // per voxel; 0 = unobserved
  std::vector<uint8_t> observed_;  // per brick
  std::vector<uint8_t> surface_;   // per brick: holds a voxel with tsdf < 1 (near a surface)
  std::vector<uint8_t> touched_;   // per brick, scratch of Integrate
  // Per coarse cell of 4^3 bricks: any brick of it has surface_ set (raycast skipping).
  std::vector<uint8_t> coarse_;
  int coarse_side_ = 0;  // coarse cells per side
};

// Writes `mesh` as a binary little-endian PLY (x y z nx ny nz float, vertex_indices uchar/int).
// Throws ReconError if the file cannot be written.
void WritePly(const Mesh& mesh, const std::string& path);

}  // namespace probeless::recon
