// Triangle meshes: the OBJ and PLY loaders and the procedural primitives (box, sphere, plane,
// cylinder, a head with face features). Positions in metres in the mesh's own (object) frame.
#pragma once

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "probeless/error/error.h"
#include "probeless/raytrace/geometry.h"

namespace probeless::raytrace {

// Bad input at the ray tracer's boundary (malformed mesh or texture file, invalid argument): one
// line naming the file (and line, for text formats) and what was expected.
class RaytraceError : public InputError {
 public:
  using InputError::InputError;
};

// An indexed triangle mesh. Optional per-vertex arrays are either empty or have positions.size()
// entries.
struct Mesh {
  std::vector<Vec3> positions;  // object frame, metres
  // Unit vertex normals (object frame) for smooth shading; empty = flat (geometric) normals.
  std::vector<Vec3> normals;
  std::vector<Vec2> uvs;     // texture coordinates; empty = none
  std::vector<Vec3> colors;  // linear RGB albedo in [0, 1] per vertex; empty = material albedo
  std::vector<std::array<uint32_t, 3>> triangles;  // counter-clockwise seen from outside

  // Throws RaytraceError (naming `what`) if an index is out of range or an optional array has the
  // wrong size.
  void Validate(const std::string& what) const;
  // Computes area-weighted smooth vertex normals from the triangles (replaces `normals`).
  void ComputeNormals();
  // Applies `transform` to positions and normals in place.
  void TransformBy(const Transform& transform);
  // Multiplies every position by `factor` (> 0) in place.
  void Scale(float factor);
  // Appends `other` (indices shifted). Optional arrays present in only one mesh are filled with
  // defaults (normals recomputed later by the caller, uv 0, colour 1).
  void Append(const Mesh& other);
  // Axis-aligned bounds {min, max}; both (0,0,0) for an empty mesh.
  std::array<Vec3, 2> Bounds() const;
};

// Reads a Wavefront OBJ file: v (optionally with r g b vertex colours), vt, vn, f (polygons
// triangulated as fans; v, v/t, v//n, v/t/n; negative indices). A vertex is created per distinct
// (v, vt, vn) triple. Ignores o, g, s, usemtl, mtllib, l and comments. Units are the file's
// (scale afterwards). Throws RaytraceError "<path>:<line>: <problem>" for malformed lines and
// "<path>: cannot open" for unreadable files.
Mesh LoadObj(const std::string& path);

// Reads a PLY file (ascii, binary_little_endian or binary_big_endian) with element vertex
// (x, y, z; optional nx ny nz, red green blue [uchar 0..255 or float 0..1, treated as sRGB for
// uchar], s t / u v / texture_u texture_v) and element face (a list of vertex indices,
// triangulated as fans). Other elements and properties are skipped. Throws RaytraceError naming
// the file (and the header line or element) on malformed input.
Mesh LoadPly(const std::string& path);

// LoadObj or LoadPly by the file extension (.obj / .ply, any case). Throws RaytraceError for
// other extensions.
Mesh LoadMesh(const std::string& path);

// An axis-aligned box centred at the origin with edge lengths `size` (metres), flat faces with
// per-face normals (24 vertices) and per-face uv in [0, 1].
Mesh MakeBox(Vec3 size);

// A UV sphere of `radius` centred at the origin, `segments` around (>= 3) and segments / 2 rings.
Mesh MakeSphere(float radius, int segments = 48);

// A rectangle in the object's x-z plane centred at the origin, normal +y, size_x by size_z metres,
// uv in [0, repeat] along both axes.
Mesh MakePlane(float size_x, float size_z, float uv_repeat = 1);

// A closed cylinder of `radius` along y from y = 0 to y = height, `segments` around (>= 3).
Mesh MakeCylinder(float radius, float height, int segments = 32);

// The procedural head: a bust (head, neck) with recognisable face features modelled as geometry
// and vertex albedo (eyes with iris and pupil, brows, nose, lips, ears). Built in the face frame
// of msgs::FaceObservation: origin at the nose bridge between the eyes, x towards the subject's
// left ear, y towards the chin, z into the head (the face looks along -z). About 0.15 m wide,
// 0.23 m from crown to chin; human proportions: pupils at x = +-32 mm on the eye line y = 0, nose
// tip ~30 mm and mouth line 62 mm below it, hairline 65 mm above it (eye-mouth / inter-ocular
// ~1.0 in a frontal view, as the tracked Yale B faces: docs/sim.md). `skin` is the linear RGB skin
// albedo.
struct HeadModel {
  Mesh mesh;
  // The 68 iBUG 300-W landmarks as points on the surface, face frame (metres), in iBUG order:
  // jaw 0-16, right brow 17-21, left brow 22-26, nose 27-35, right eye 36-41, left eye 42-47,
  // mouth 48-67 ("right" = the subject's right, i.e. image left for a frontal face).
  std::vector<Vec3> landmarks;
};
HeadModel MakeHead(Vec3 skin = {0.62f, 0.42f, 0.33f}, int resolution = 96);

}  // namespace probeless::raytrace
