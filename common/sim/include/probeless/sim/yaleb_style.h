// Ground truth for face light training: a Yale-B-style data set rendered with probeless_raytrace.
// A head (the procedural head, or the ICT FaceKit mesh) in frontal pose, cropped and aligned to
// the canonical 168 x 192 crop of docs/face_light.md (eyes (32, 44) / (133, 44), nose tip (83, 95),
// mouth (83, 147)), one "subject" per seed-derived albedo and shape, lit by the 64 Extended Yale B
// light directions (optionally more from behind and coloured), written with Yale B file names
// (yaleBxx/yaleBxx_P00A±aaaE±ee.pgm). Reference: docs/sim.md, section "Yale-B-style data sets".
//
// Light frame = camera frame of the crop = the face frame of msgs::FaceObservation (x towards the
// subject's left ear = image right, y down, z into the head); Yale B azimuth A / elevation E give
// the direction towards the light (-sin A cos E, -sin E, -cos A cos E): positive azimuth = light
// from the subject's right = image left, positive elevation = from above.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "probeless/raytrace/geometry.h"
#include "probeless/raytrace/render.h"
#include "probeless/sim/scenario.h"

namespace probeless::sim {

// One light direction of the data set, in Yale B degrees (integers, as in the file names).
struct YaleBLightDirection {
  int azimuth_deg = 0;
  int elevation_deg = 0;
  friend bool operator==(const YaleBLightDirection&, const YaleBLightDirection&) = default;
};

// The 64 light directions of Extended Yale B (pose P00), sorted as the file names sort.
std::vector<YaleBLightDirection> YaleBLightDirections();

// The directions the Yale B files of `subject_dir` (a yaleBxx/ folder) are named after, sorted as
// the file names; empty if the folder holds none.
std::vector<YaleBLightDirection> YaleBLightDirectionsFromFolder(const std::string& subject_dir);

// 28 directions from behind the head that Yale B lacks: azimuth ±140, ±155, ±170, +180 at
// elevations -20, 0, +20, +45.
std::vector<YaleBLightDirection> BehindLightDirections();

// Unit direction towards the light in the light frame: (-sin A cos E, -sin E, -cos A cos E).
raytrace::Vec3 LightDirectionFromYaleB(double azimuth_deg, double elevation_deg);

// "yaleB07_P00A-035E+15.pgm" for subject 7, (-35, 15) and extension "pgm". Throws ScenarioError
// unless 1 <= subject <= 99, |azimuth| <= 180 and |elevation| <= 90.
std::string YaleBFileName(int subject, YaleBLightDirection light, const std::string& extension);

// A pixel position (x right, y down, (0, 0) = centre of the top-left pixel).
struct Pixel {
  double x = 0;
  double y = 0;
};

// The four alignment points of the canonical crop (face_light::kCanonical*), crop pixels, in the
// order subject's right eye, subject's left eye, nose tip, mouth centre.
inline constexpr std::array<Pixel, 4> kYaleBCanonicalPoints{
    {{32, 44}, {133, 44}, {83, 95}, {83, 147}}};

struct YaleBStyleOptions {
  int subjects = 10;      // rendered subjects, numbered first_subject, first_subject + 1, ...
  int first_subject = 1;  // 1..99; subject numbers must stay <= 99
  int width = 168;        // image size; the canonical points scale with width / 168 and
  int height = 192;       // height / 192 (face_light loads only 168 x 192)
  bool rgb = false;       // also write .ppm images under coloured lights (+ colour sidecar)
  bool behind = false;    // add BehindLightDirections()
  uint64_t seed = 1;      // subject appearance and light colours; same seed -> same bytes
  std::string mesh = "procedural";  // "procedural" or "ict"
  std::string ict_path;             // the ICT OBJ for mesh "ict" (see FindDataFile)
  // Light directions; empty = YaleBLightDirections() (plus BehindLightDirections() if behind).
  std::vector<YaleBLightDirection> lights;
  // Directional light: a white surface facing it reads `light_level` (linear, 1 = 255).
  double light_level = 0.9;
  // Ambient: uniform environment radiance, so a white surface reads `ambient` everywhere
  // (unshadowed), like the room light in every Yale B image.
  double ambient = 0.03;
  bool shadows = true;
  int head_resolution = 96;  // procedural head tessellation (raytrace::MakeHead)
  int threads = 2;           // render threads
  // Called after each written image with (images done, images total).
  std::function<void(uint64_t, uint64_t)> progress;

  // Throws ScenarioError (one line, naming the option) for out-of-range values.
  void Validate() const;
};

// One rendered image: 8-bit values, linear in radiance (value = round(255 clamp(radiance))).
struct YaleBStyleImage {
  YaleBLightDirection light;
  std::string file_name;        // Yale B name (".pgm" or ".ppm")
  int channels = 1;             // 1 = grey (white light), 3 = RGB (coloured light)
  raytrace::Vec3 light_color;   // linear RGB of the light, max channel 1; (1, 1, 1) for grey
  std::vector<uint8_t> pixels;  // width * height * channels, row-major
};

// One subject: its appearance and where its landmarks land.
struct YaleBStyleSubject {
  int subject = 0;
  raytrace::Vec3 skin;         // linear RGB base albedo
  raytrace::Vec3 shape_scale;  // x, y, z scale of the head before alignment
  int blotches = 0;            // albedo blotches painted on the skin
  raytrace::Camera camera;     // the crop camera (intrinsics, roll), face frame = world frame
  // The four alignment points (kYaleBCanonicalPoints order) projected into the image, and their
  // largest distance to the (scaled) canonical points, pixels.
  std::array<Pixel, 4> aligned_points{};
  double alignment_error_px = 0;
  // The 68 iBUG landmarks projected into the image (procedural head only; empty for ICT).
  std::vector<Pixel> landmarks;
};

// Renders subject number `subject` under every light of `options` (grey images first in light
// order, then, with rgb, the RGB images in light order) plus the ambient-only grey image (last,
// file "yaleBxx_P00_Ambient.pgm"). Deterministic in (options, subject): byte-identical for any
// thread count. Throws ScenarioError for invalid options or an unreadable ICT mesh.
YaleBStyleSubject RenderYaleBStyleSubject(const YaleBStyleOptions& options, int subject,
                                          std::vector<YaleBStyleImage>* images);

// Summary of a written data set.
struct YaleBStyleSummary {
  int subjects = 0;
  uint64_t images = 0;  // files written (pgm, ppm, ambient)
  double max_alignment_error_px = 0;
};

// Writes the data set to out_dir: yaleBxx/ folders with the images (binary PGM / PPM, no
// comments), yaleBxx/yaleBxx_P00_lights.txt (one line per image: file azimuth elevation dx dy dz
// r g b; the RGB light colour of .ppm files, 1 1 1 for .pgm), and out_dir/yaleb_style.json (the
// options, per-subject appearance and alignment). Throws ScenarioError for invalid options,
// unwritable files ("<path>: cannot write") or an unreadable ICT mesh.
YaleBStyleSummary WriteYaleBStyleDataset(const std::string& out_dir,
                                         const YaleBStyleOptions& options);

}  // namespace probeless::sim
