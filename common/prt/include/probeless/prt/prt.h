// Precomputed radiance transfer (PRT) for virtual objects: Knorr & Kurz 2014 §4.2, eq. 20.
//
// Transfer convention (the same as msgs::TransferBuffer, per vertex instead of per pixel): for a
// vertex x with unit normal n, coefficient k of its transfer vector is
//   T_k(x) = (1/pi) * integral V(x, w) Y_k(w) max(0, w.n) dw            (K&K eq. 20, divided by pi)
// so the radiance leaving a Lambertian vertex of albedo a under distant light with SH coefficients
// L_k (msgs::ShLight convention, expressed in the frame the mesh was baked in) is
// a * sum_k T_k L_k. Without occlusion T_k = A_l Y_k(n) / pi (A_l: sh::ClampedCosineCoefficient).
// V = 1 if the ray from x along w leaves the scene (the object itself and its occluders) unhit.
// With the optional interreflection bounce, T also contains one diffuse bounce off the object
// itself (Sloan et al. 2002, "interreflected transfer"): T1 = T0 + mean over occluded samples of
// albedo(hit) * T0(hit).
//
// Sampling: per vertex, a k x k stratified grid over the unit square (k = sqrt(samples)), jittered
// by a fixed-seed generator keyed by (seed, vertex index), mapped to the cosine-weighted hemisphere
// around n (pdf cos/pi), so T_k is the plain mean of V Y_k over the samples. Results do not depend
// on the thread count.
//
// Errors: invalid arguments and malformed files throw PrtError with one line naming the file or
// argument and what was expected.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "probeless/error/error.h"
#include "probeless/raytrace/geometry.h"
#include "probeless/raytrace/mesh.h"

namespace probeless::prt {

class PrtError : public InputError {
 public:
  using InputError::InputError;
};

// A mesh with one transfer vector per vertex. The mesh is expressed in its bake frame (e.g. the
// face frame of msgs::FaceObservation for face-anchored objects); SH lights must be rotated into
// that frame before the dot product.
struct TransferMesh {
  raytrace::Mesh mesh;  // positions, normals (always present), optional colours (linear albedo)
  int bands = 0;        // 1..5; coefficients per vertex: bands^2
  std::vector<float> transfer;  // vertex-major: vertex v's coefficient k at v * bands^2 + k

  // Coefficients per vertex: bands^2.
  int coefficient_count() const { return bands * bands; }
  // The transfer vector of vertex v (bands^2 values). No bounds check beyond the vector's.
  std::span<const float> VertexTransfer(size_t v) const {
    return {transfer.data() + v * coefficient_count(), static_cast<size_t>(coefficient_count())};
  }
  // Throws PrtError (naming `what`) unless bands is 1..5, the mesh is valid, has normals, and
  // transfer has positions.size() * bands^2 entries.
  void Validate(const std::string& what) const;
};

// A mesh occluding the bake (not baked itself), placed in the bake frame.
struct Occluder {
  raytrace::Mesh mesh;
  raytrace::Transform placement;  // occluder frame -> bake frame
};

struct BakeOptions {
  int bands = 3;                            // 1..5 (3 = 9 coefficients, the paper's; 4 = 16)
  int samples = 256;                        // rays per vertex; rounded down to a square k*k, k >= 1
  uint64_t seed = 1;                        // fixed seed of the stratified jitter
  bool self_occlusion = true;               // the object shadows itself
  bool interreflection = false;             // one diffuse bounce off the object (Sloan 2002)
  raytrace::Vec3 albedo{0.8f, 0.8f, 0.8f};  // bounce albedo where the mesh has no colours
  float ray_epsilon = 1e-4f;                // metres: ray origins offset along the vertex normal
  int threads = 2;                          // worker threads (>= 1)
  // Called now and then from the calling thread with (vertices done, vertex count).
  std::function<void(size_t, size_t)> progress;
};

struct BakeStats {
  uint64_t shadow_rays = 0;  // occlusion rays traced (plus bounce rays, counted separately)
  uint64_t bounce_rays = 0;  // closest-hit rays of the interreflection pass
  double seconds = 0;        // wall time of the whole bake (scene build included)
  double trace_seconds = 0;  // wall time of the ray passes only (generation, tracing, SH sums)
};

// Bakes the transfer of every vertex of `mesh` (bake frame) with `occluders` (K&K eq. 20 by
// stratified Monte-Carlo with Embree occlusion rays, batched through raytrace::Scene::Occluded).
// Vertex normals are computed if the mesh has none. Throws PrtError for an invalid mesh or options.
TransferMesh Bake(const raytrace::Mesh& mesh, std::span<const Occluder> occluders,
                  const BakeOptions& options, BakeStats* stats = nullptr);

// The analytic unshadowed transfer of unit normal n: T_k = A_l Y_k(n) / pi, bands^2 values.
std::vector<float> UnshadowedTransfer(const raytrace::Vec3& n, int bands);

// Writes `mesh` as a PRT file (format in docs/render.md: magic "PBLPRT01", little-endian header,
// positions, normals, optional colours, triangles, transfer). Throws PrtError if it cannot write.
void SavePrt(const TransferMesh& mesh, const std::string& path);
// Reads a PRT file. Throws PrtError "<path>: <problem>" for a missing, truncated or malformed file.
TransferMesh LoadPrt(const std::string& path);

// SH rotation: the bands^2 x bands^2 matrix M (row-major) with L_B = M L_A, where L_A are the
// coefficients of a light in frame A, `b_to_a` rotates directions of frame B into frame A and
// L_B(w) = L_A(b_to_a w). Exact for every band (M_nm = integral Y_n(w) Y_m(b_to_a w) dw by a
// Gauss-Legendre rule exact for these degrees). Throws PrtError unless 1 <= bands <= 5.
std::vector<double> ShRotationMatrix(const raytrace::Mat3& b_to_a, int bands);

}  // namespace probeless::prt
