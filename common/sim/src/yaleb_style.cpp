// Yale-B-style data sets rendered with probeless_raytrace (docs/sim.md).
#include "probeless/sim/yaleb_style.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <numbers>
#include <optional>
#include <sstream>
#include <string_view>

#include "probeless/dataset/yaleb.h"
#include "probeless/parse/number.h"
#include "probeless/raytrace/mesh.h"
#include "probeless/raytrace/render.h"
#include "probeless/raytrace/scene.h"

namespace probeless::sim {
namespace {

namespace fs = std::filesystem;
using raytrace::Mesh;
using raytrace::Vec3;

constexpr double kDeg = std::numbers::pi / 180;
// Distance of the face origin from the camera: far enough that the alignment is near-affine.
constexpr double kHeadDistanceM = 1.5;
constexpr double kCanonicalWidth = 168;
constexpr double kCanonicalHeight = 192;

// SplitMix64: a portable, seedable generator (std distributions differ between libraries).
class Random {
 public:
  explicit Random(uint64_t seed) : state_(seed) {}
  uint64_t Next() {
    uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [lo, hi).
  double Uniform(double lo, double hi) { return lo + (hi - lo) * (Next() >> 11) * 0x1.0p-53; }

 private:
  uint64_t state_;
};

uint64_t SubjectSeed(uint64_t seed, int subject, uint64_t stream) {
  Random r(seed * 0x100000001B3ull + static_cast<uint64_t>(subject) * 0x9E3779B9ull + stream);
  r.Next();
  return r.Next();
}

[[noreturn]] void Fail(const std::string& message) { throw ScenarioError(message); }

// The alignment points of a head in the face frame: right eye, left eye, nose tip, mouth.
using KeyPoints = std::array<Vec3, 4>;

Vec3 Mean(const std::vector<Vec3>& points, int first, int last) {
  Vec3 sum;
  for (int i = first; i <= last; ++i) sum += points[i];
  return sum / static_cast<float>(last - first + 1);
}

// The procedural head's alignment points from its 68 iBUG landmarks (the combinations the face
// tracker fits: eye contour means 36-41 / 42-47, nose tip 30, inner-lip mean 60-67).
KeyPoints ProceduralKeyPoints(const std::vector<Vec3>& landmarks) {
  return {Mean(landmarks, 36, 41), Mean(landmarks, 42, 47), landmarks[30], Mean(landmarks, 60, 67)};
}

// The ICT FaceKit generic neutral mesh, converted to the face frame (cm -> m, rotated 180 degrees
// about x), without the transparent shells (eye occlusion, lacrimal fluid, eye blend, lashes), with
// vertex albedo per material, and its alignment points: iris centroids, the front-most midline
// vertex of the face (nose tip) and the mean of the teeth (the lip line of the closed mouth).
struct IctHead {
  Mesh mesh;
  KeyPoints keys{};
  std::vector<uint8_t> is_skin;  // per vertex: painted with the subject's skin (and blotches)
};

IctHead LoadIctHead(const std::string& path) {
  std::ifstream in(path);
  if (!in) Fail(path + ": cannot open the ICT mesh");
  enum Part { kSkin, kGums, kTeeth, kSclera, kIrisLeft, kIrisRight, kDrop };
  std::vector<Vec3> positions;
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<int> part_of_vertex;
  Part part = kSkin;
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    if (line.starts_with("v ")) {
      Vec3 p;
      if (std::sscanf(line.c_str() + 2, "%f %f %f", &p.x, &p.y, &p.z) != 3) {
        Fail(path + ":" + std::to_string(line_number) + ": bad vertex");
      }
      positions.push_back({p.x * 0.01f, -p.y * 0.01f, -p.z * 0.01f});
      part_of_vertex.push_back(-1);
    } else if (line.starts_with("usemtl ")) {
      const std::string m = line.substr(7);
      part = m.starts_with("M_Face") || m.starts_with("M_BackHead") ? kSkin
             : m.starts_with("M_GumsTongue")                        ? kGums
             : m.starts_with("M_Teeth")                             ? kTeeth
             : m.starts_with("M_Sclera")                            ? kSclera
             : m.starts_with("M_IrisLeft")                          ? kIrisLeft
             : m.starts_with("M_IrisRight")                         ? kIrisRight
                                                                    : kDrop;
    } else if (line.starts_with("f ")) {
      if (part == kDrop) continue;
      std::istringstream words(line.substr(2));
      std::vector<uint32_t> face;
      std::string word;
      while (words >> word) {
        // The vertex part of "v/vt/vn", whole: strtol took "12abc" as 12 and "abc" as 0.
        const std::optional<long> parsed =
            parse::TryParseInteger<long>(std::string_view(word).substr(0, word.find('/')));
        if (!parsed || *parsed == 0) {
          Fail(path + ":" + std::to_string(line_number) + ": malformed face index '" + word + "'");
        }
        const long index = *parsed;
        const long resolved = index < 0 ? static_cast<long>(positions.size()) + index : index - 1;
        if (resolved < 0 || resolved >= static_cast<long>(positions.size())) {
          Fail(path + ":" + std::to_string(line_number) + ": face index out of range");
        }
        face.push_back(static_cast<uint32_t>(resolved));
        part_of_vertex[resolved] = part;
      }
      for (size_t k = 2; k < face.size(); ++k) triangles.push_back({face[0], face[k - 1], face[k]});
    }
  }
  if (triangles.empty()) Fail(path + ": no faces in the ICT mesh");
  // Keep the used vertices only.
  IctHead head;
  std::vector<uint32_t> remap(positions.size(), UINT32_MAX);
  std::array<std::vector<Vec3>, 7> by_part;
  for (size_t i = 0; i < positions.size(); ++i) {
    if (part_of_vertex[i] < 0) continue;
    remap[i] = static_cast<uint32_t>(head.mesh.positions.size());
    head.mesh.positions.push_back(positions[i]);
    const int p = part_of_vertex[i];
    head.is_skin.push_back(p == kSkin);
    head.mesh.colors.push_back(p == kGums     ? Vec3{0.45f, 0.16f, 0.15f}
                               : p == kTeeth  ? Vec3{0.75f, 0.72f, 0.62f}
                               : p == kSclera ? Vec3{0.8f, 0.78f, 0.74f}
                               : p == kSkin   ? Vec3{0.6f, 0.45f, 0.36f}
                                              : Vec3{0.12f, 0.08f, 0.05f});
    by_part[p].push_back(positions[i]);
  }
  for (auto& t : triangles) head.mesh.triangles.push_back({remap[t[0]], remap[t[1]], remap[t[2]]});
  head.mesh.ComputeNormals();
  if (by_part[kIrisLeft].empty() || by_part[kIrisRight].empty() || by_part[kTeeth].empty()) {
    Fail(path + ": the ICT mesh lacks the iris or teeth materials needed for alignment");
  }
  const auto centroid = [](const std::vector<Vec3>& v) {
    return Mean(v, 0, static_cast<int>(v.size()) - 1);
  };
  // The ICT "left" iris is the subject's left (+x in the face frame).
  Vec3 right = centroid(by_part[kIrisRight]), left = centroid(by_part[kIrisLeft]);
  if (right.x > left.x) std::swap(right, left);
  Vec3 nose{0, 0, 1e9f};
  const float eye_y = (right.y + left.y) / 2;
  for (const Vec3& p : by_part[kSkin]) {
    if (std::abs(p.x) < 0.01f && p.y > eye_y && p.z < nose.z) nose = p;
  }
  const Vec3 teeth = centroid(by_part[kTeeth]);
  head.keys = {right, left, nose, Vec3{0, teeth.y, nose.z}};
  return head;
}

// Least-squares similarity p -> (a x - b y + tx, b x + a y + ty) from `from` onto `to`.
std::array<double, 4> FitSimilarity(const std::array<Pixel, 4>& from,
                                    const std::array<Pixel, 4>& to) {
  double mfx = 0, mfy = 0, mtx = 0, mty = 0;
  for (int i = 0; i < 4; ++i) {
    mfx += from[i].x / 4, mfy += from[i].y / 4, mtx += to[i].x / 4, mty += to[i].y / 4;
  }
  double sxx = 0, sab = 0, sba = 0;
  for (int i = 0; i < 4; ++i) {
    const double fx = from[i].x - mfx, fy = from[i].y - mfy;
    const double tx = to[i].x - mtx, ty = to[i].y - mty;
    sxx += fx * fx + fy * fy;
    sab += fx * tx + fy * ty;
    sba += fx * ty - fy * tx;
  }
  const double a = sab / sxx, b = sba / sxx;
  return {a, b, mtx - (a * mfx - b * mfy), mty - (b * mfx + a * mfy)};
}

// Warps y (face frame) piecewise linearly through the knots from[k] -> to[k] (ascending), slope 1
// above the first and below the last knot (continuous).
void WarpY(Mesh& mesh, KeyPoints& keys, std::vector<Vec3>* landmarks,
           const std::array<double, 3>& from, const std::array<double, 3>& to) {
  const auto warp = [&](float y) {
    if (y <= from[0]) return static_cast<float>(y - from[0] + to[0]);
    if (y >= from[2]) return static_cast<float>(y - from[2] + to[2]);
    const int k = y < from[1] ? 0 : 1;
    const double t = (y - from[k]) / (from[k + 1] - from[k]);
    return static_cast<float>(to[k] + t * (to[k + 1] - to[k]));
  };
  for (Vec3& p : mesh.positions) p.y = warp(p.y);
  for (Vec3& p : keys) p.y = warp(p.y);
  if (landmarks) {
    for (Vec3& p : *landmarks) p.y = warp(p.y);
  }
}

// Warps the head in y so that the nose tip and the mouth sit at the canonical fractions of the
// eye-to-mouth drop relative to the eye distance, then refines the knots on the perspective
// projection (the nose tip is nearer the camera): the four points then fit a similarity to well
// under a pixel. The eyes keep their height.
void WarpToCanonicalProportions(Mesh& mesh, KeyPoints& keys, std::vector<Vec3>* landmarks,
                                int width, int height);

Pixel Project(const raytrace::Camera& camera, Vec3 world) {
  const Vec3 p = camera.camera_to_world.Inverse().Apply(world);
  return {camera.fx * p.x / p.z + camera.cx, camera.fy * p.y / p.z + camera.cy};
}

// The canonical points scaled to an image of width x height.
std::array<Pixel, 4> TargetPoints(int width, int height) {
  std::array<Pixel, 4> out;
  for (int i = 0; i < 4; ++i) {
    out[i] = {(kYaleBCanonicalPoints[i].x + 0.5) * width / kCanonicalWidth - 0.5,
              (kYaleBCanonicalPoints[i].y + 0.5) * height / kCanonicalHeight - 0.5};
  }
  return out;
}

// The crop camera: a similarity (roll about the optical axis, focal length, principal point)
// from the head's projection with a unit camera onto the canonical points, scaled per axis to the
// image size. The head sits at (0, 0, kHeadDistanceM) with the face frame's axes.
raytrace::Camera AlignCamera(const KeyPoints& keys, int width, int height) {
  std::array<Pixel, 4> normalised, canonical;
  for (int i = 0; i < 4; ++i) {
    const Vec3 p = keys[i] + Vec3{0, 0, static_cast<float>(kHeadDistanceM)};
    normalised[i] = {p.x / p.z, p.y / p.z};
    canonical[i] = kYaleBCanonicalPoints[i];
  }
  const auto [a, b, tx, ty] = FitSimilarity(normalised, canonical);
  const double kx = width / kCanonicalWidth, ky = height / kCanonicalHeight;
  raytrace::Camera camera;
  camera.width = width;
  camera.height = height;
  const double scale = std::hypot(a, b), theta = std::atan2(b, a);
  camera.fx = kx * scale;
  camera.fy = ky * scale;
  camera.cx = kx * (tx + 0.5) - 0.5;
  camera.cy = ky * (ty + 0.5) - 0.5;
  // Normalised coordinates of a camera rolled by phi are those of the unrolled one rotated by
  // -phi; the similarity rotates by theta, so phi = -theta.
  camera.camera_to_world.rotation = raytrace::Mat3::AxisAngle({0, 0, 1}, -theta);
  return camera;
}

void WarpToCanonicalProportions(Mesh& mesh, KeyPoints& keys, std::vector<Vec3>* landmarks,
                                int width, int height) {
  const auto& c = kYaleBCanonicalPoints;
  const double metres_per_px = (keys[1].x - keys[0].x) / (c[1].x - c[0].x);
  const double eye_y = (keys[0].y + keys[1].y) / 2;
  const double canonical_eye_y = (c[0].y + c[1].y) / 2;
  WarpY(mesh, keys, landmarks, {eye_y, keys[2].y, keys[3].y},
        {eye_y, eye_y + (c[2].y - canonical_eye_y) * metres_per_px,
         eye_y + (c[3].y - canonical_eye_y) * metres_per_px});
  const std::array<Pixel, 4> targets = TargetPoints(width, height);
  const Vec3 offset{0, 0, static_cast<float>(kHeadDistanceM)};
  for (int iteration = 0; iteration < 3; ++iteration) {
    const raytrace::Camera camera = AlignCamera(keys, width, height);
    std::array<double, 3> from{(keys[0].y + keys[1].y) / 2.0, keys[2].y, keys[3].y}, to = from;
    for (int k = 0; k < 3; ++k) {
      const Pixel p = Project(camera, keys[k + 1] + offset);
      const double target = k == 0 ? (targets[0].y + targets[1].y) / 2 : targets[k + 1].y;
      const double actual = k == 0 ? (p.y + Project(camera, keys[0] + offset).y) / 2 : p.y;
      const double z = kHeadDistanceM + (k == 0 ? keys[0].z : keys[k + 1].z);
      to[k] += (target - actual) * z / camera.fy;
    }
    WarpY(mesh, keys, landmarks, from, to);
  }
  mesh.ComputeNormals();
}

struct SubjectLook {
  Vec3 skin;
  Vec3 shape_scale;
  struct Blotch {
    Vec3 centre;
    float radius;
    Vec3 factor;
  };
  std::vector<Blotch> blotches;
};

// Skin tone between light and dark with a little hue jitter, a few albedo blotches (moles,
// freckle patches, redness) on the front of the face, and a slight width / depth scaling.
SubjectLook MakeLook(uint64_t seed, int subject) {
  Random r(SubjectSeed(seed, subject, 1));
  SubjectLook look;
  const Vec3 light{0.80f, 0.62f, 0.52f}, dark{0.28f, 0.17f, 0.12f};
  const float t = static_cast<float>(r.Uniform(0, 1));
  look.skin = light * (1 - t) + dark * t;
  look.skin.x *= static_cast<float>(r.Uniform(0.95, 1.05));
  look.skin.y *= static_cast<float>(r.Uniform(0.95, 1.05));
  look.skin.z *= static_cast<float>(r.Uniform(0.92, 1.08));
  look.shape_scale = {static_cast<float>(r.Uniform(0.95, 1.05)), 1.0f,
                      static_cast<float>(r.Uniform(0.92, 1.08))};
  const int n = 2 + static_cast<int>(r.Uniform(0, 4));  // 2..5
  for (int k = 0; k < n; ++k) {
    SubjectLook::Blotch b;
    b.centre = {static_cast<float>(r.Uniform(-0.06, 0.06)),
                static_cast<float>(r.Uniform(-0.05, 0.1)), -0.05f};
    b.radius = static_cast<float>(r.Uniform(0.006, 0.025));
    const double kind = r.Uniform(0, 1);
    const float strength = static_cast<float>(r.Uniform(0.15, 0.4));
    b.factor =
        kind < 0.4 ? Vec3{1 - strength, 1 - 1.2f * strength, 1 - 1.3f * strength}  // brown
        : kind < 0.7
            ? Vec3{1 + 0.3f * strength, 1 - 0.6f * strength, 1 - 0.6f * strength}   // redness
            : Vec3{1 + 0.5f * strength, 1 + 0.5f * strength, 1 + 0.5f * strength};  // pale patch
    look.blotches.push_back(b);
  }
  return look;
}

// Multiplies the albedo of skin vertices by the blotches (Gaussian falloff in x, y, only on the
// front half of the head).
void PaintBlotches(Mesh& mesh, const std::vector<uint8_t>& is_skin, const SubjectLook& look) {
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    if (!is_skin[i]) continue;
    const Vec3 p = mesh.positions[i];
    if (p.z > 0.02f) continue;
    Vec3& c = mesh.colors[i];
    for (const auto& b : look.blotches) {
      const float dx = p.x - b.centre.x, dy = p.y - b.centre.y;
      const float w = std::exp(-(dx * dx + dy * dy) / (b.radius * b.radius));
      c = c * (Vec3{1, 1, 1} + (b.factor - Vec3{1, 1, 1}) * w);
    }
    c = {std::clamp(c.x, 0.0f, 1.0f), std::clamp(c.y, 0.0f, 1.0f), std::clamp(c.z, 0.0f, 1.0f)};
  }
}

// A saturated-ish light colour per (subject, light), max channel 1.
Vec3 LightColor(uint64_t seed, int subject, size_t light_index) {
  Random r(SubjectSeed(seed, subject, 1000 + light_index));
  Vec3 c{static_cast<float>(r.Uniform(0.35, 1)), static_cast<float>(r.Uniform(0.35, 1)),
         static_cast<float>(r.Uniform(0.35, 1))};
  return c / std::max({c.x, c.y, c.z});
}

std::vector<uint8_t> ToBytes(const std::vector<float>& linear_rgb, int channels) {
  const size_t n = linear_rgb.size() / 3;
  std::vector<uint8_t> out(n * channels);
  const auto byte = [](double v) {
    return static_cast<uint8_t>(std::lround(255 * std::clamp(v, 0.0, 1.0)));
  };
  for (size_t i = 0; i < n; ++i) {
    const float* p = &linear_rgb[i * 3];
    if (channels == 1) {
      out[i] = byte(0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]);
    } else {
      for (int c = 0; c < 3; ++c) out[i * 3 + c] = byte(p[c]);
    }
  }
  return out;
}

void WriteBinary(const fs::path& path, const std::string& header,
                 const std::vector<uint8_t>& data) {
  std::ofstream out(path, std::ios::binary);
  out << header;
  out.write(reinterpret_cast<const char*>(data.data()), static_cast<std::streamsize>(data.size()));
  out.close();
  if (!out) Fail(path.string() + ": cannot write");
}

std::string Format(const char* format, auto... args) {
  char buffer[256];
  std::snprintf(buffer, sizeof buffer, format, args...);
  return buffer;
}

std::vector<YaleBLightDirection> LightsOf(const YaleBStyleOptions& options) {
  if (!options.lights.empty()) return options.lights;
  std::vector<YaleBLightDirection> lights = YaleBLightDirections();
  if (options.behind) {
    for (const auto& l : BehindLightDirections()) lights.push_back(l);
  }
  return lights;
}

}  // namespace

std::vector<YaleBLightDirection> YaleBLightDirections() {
  // Extended Yale B, pose P00: the 64 (azimuth, elevation) pairs of the file names, in file-name
  // order (the sign sorts '+' before '-').
  static const int kTable[64][2] = {
      {0, 0},     {0, 20},   {0, 45},    {0, 90},    {0, -20},   {0, -35},    {5, 10},
      {5, -10},   {10, 0},   {10, -20},  {15, 20},   {20, 10},   {20, -10},   {20, -40},
      {25, 0},    {35, 15},  {35, 40},   {35, 65},   {35, -20},  {50, 0},     {50, -40},
      {60, 20},   {60, -20}, {70, 0},    {70, 45},   {70, -35},  {85, 20},    {85, -20},
      {95, 0},    {110, 15}, {110, 40},  {110, 65},  {110, -20}, {120, 0},    {130, 20},
      {-5, 10},   {-5, -10}, {-10, 0},   {-10, -20}, {-15, 20},  {-20, 10},   {-20, -10},
      {-20, -40}, {-25, 0},  {-35, 15},  {-35, 40},  {-35, 65},  {-35, -20},  {-50, 0},
      {-50, -40}, {-60, 20}, {-60, -20}, {-70, 0},   {-70, 45},  {-70, -35},  {-85, 20},
      {-85, -20}, {-95, 0},  {-110, 15}, {-110, 40}, {-110, 65}, {-110, -20}, {-120, 0},
      {-130, 20}};
  std::vector<YaleBLightDirection> out;
  for (const auto& [a, e] : kTable) out.push_back({a, e});
  return out;
}

std::vector<YaleBLightDirection> YaleBLightDirectionsFromFolder(const std::string& subject_dir) {
  std::vector<std::string> names;
  std::error_code error;
  for (fs::directory_iterator it(subject_dir, error), end; !error && it != end;
       it.increment(error)) {
    names.push_back(it->path().filename().string());
  }
  std::sort(names.begin(), names.end());
  std::vector<YaleBLightDirection> out;
  for (const std::string& n : names) {
    if (const auto parsed = dataset::ParseYaleBName(n)) {
      out.push_back({parsed->azimuth_deg, parsed->elevation_deg});
    }
  }
  return out;
}

std::vector<YaleBLightDirection> BehindLightDirections() {
  std::vector<YaleBLightDirection> out;
  for (int a : {140, 155, 170, 180, -140, -155, -170}) {
    for (int e : {0, 20, 45, -20}) out.push_back({a, e});
  }
  return out;
}

Vec3 LightDirectionFromYaleB(double azimuth_deg, double elevation_deg) {
  const double a = azimuth_deg * kDeg, e = elevation_deg * kDeg;
  return {static_cast<float>(-std::sin(a) * std::cos(e)), static_cast<float>(-std::sin(e)),
          static_cast<float>(-std::cos(a) * std::cos(e))};
}

std::string YaleBFileName(int subject, YaleBLightDirection light, const std::string& extension) {
  if (subject < 1 || subject > 99 || std::abs(light.azimuth_deg) > 180 ||
      std::abs(light.elevation_deg) > 90) {
    Fail(
        Format("Yale B name: subject %d, azimuth %d, elevation %d out of range (1..99, +-180, "
               "+-90)",
               subject, light.azimuth_deg, light.elevation_deg));
  }
  return Format("yaleB%02d_P00A%c%03dE%c%02d.%s", subject, light.azimuth_deg < 0 ? '-' : '+',
                std::abs(light.azimuth_deg), light.elevation_deg < 0 ? '-' : '+',
                std::abs(light.elevation_deg), extension.c_str());
}

void YaleBStyleOptions::Validate() const {
  if (subjects < 1) Fail("yaleb-style: subjects must be >= 1");
  if (first_subject < 1 || first_subject + subjects - 1 > 99) {
    Fail("yaleb-style: subject numbers must lie in 1..99");
  }
  if (width < 16 || height < 16 || width > 4096 || height > 4096) {
    Fail("yaleb-style: size must be between 16x16 and 4096x4096");
  }
  if (mesh != "procedural" && mesh != "ict") {
    Fail("yaleb-style: mesh must be 'procedural' or 'ict', got '" + mesh + "'");
  }
  if (mesh == "ict" && ict_path.empty()) Fail("yaleb-style: mesh 'ict' needs the ICT OBJ path");
  if (!(light_level > 0)) Fail("yaleb-style: light level must be > 0");
  if (!(ambient >= 0)) Fail("yaleb-style: ambient must be >= 0");
  if (head_resolution < 16) Fail("yaleb-style: head resolution must be >= 16");
  if (threads < 1) Fail("yaleb-style: threads must be >= 1");
}

YaleBStyleSubject RenderYaleBStyleSubject(const YaleBStyleOptions& options, int subject,
                                          std::vector<YaleBStyleImage>* images) {
  options.Validate();
  const SubjectLook look = MakeLook(options.seed, subject);
  YaleBStyleSubject out;
  out.subject = subject;
  out.skin = look.skin;
  out.shape_scale = look.shape_scale;
  out.blotches = static_cast<int>(look.blotches.size());

  Mesh mesh;
  KeyPoints keys;
  std::vector<uint8_t> is_skin;
  std::vector<Vec3> landmarks;
  if (options.mesh == "procedural") {
    raytrace::HeadModel head = raytrace::MakeHead(look.skin, options.head_resolution);
    mesh = std::move(head.mesh);
    landmarks = std::move(head.landmarks);
    // Skin = vertices whose colour is the skin albedo.
    for (const Vec3& c : mesh.colors) {
      is_skin.push_back(c.x == look.skin.x && c.y == look.skin.y && c.z == look.skin.z);
    }
  } else {
    static std::mutex mutex;
    static std::string cached_path;
    static std::shared_ptr<const IctHead> cached;
    std::shared_ptr<const IctHead> ict;
    {
      std::lock_guard lock(mutex);
      if (!cached || cached_path != options.ict_path) {
        cached = std::make_shared<IctHead>(LoadIctHead(options.ict_path));
        cached_path = options.ict_path;
      }
      ict = cached;
    }
    mesh = ict->mesh;
    keys = ict->keys;
    is_skin = ict->is_skin;
    for (size_t i = 0; i < mesh.colors.size(); ++i) {
      if (is_skin[i]) mesh.colors[i] = look.skin;
    }
  }
  // Shape: width and depth scaling about the face origin.
  for (Vec3& p : mesh.positions) p = p * look.shape_scale;
  for (Vec3& p : landmarks) p = p * look.shape_scale;
  if (!landmarks.empty()) {
    keys = ProceduralKeyPoints(landmarks);
  } else {
    for (Vec3& p : keys) p = p * look.shape_scale;
  }
  PaintBlotches(mesh, is_skin, look);
  WarpToCanonicalProportions(mesh, keys, landmarks.empty() ? nullptr : &landmarks, options.width,
                             options.height);

  out.camera = AlignCamera(keys, options.width, options.height);
  const Vec3 offset{0, 0, static_cast<float>(kHeadDistanceM)};
  const std::array<Pixel, 4> targets = TargetPoints(options.width, options.height);
  for (int i = 0; i < 4; ++i) {
    out.aligned_points[i] = Project(out.camera, keys[i] + offset);
    out.alignment_error_px = std::max(
        out.alignment_error_px,
        std::hypot(out.aligned_points[i].x - targets[i].x, out.aligned_points[i].y - targets[i].y));
  }
  for (const Vec3& p : landmarks) out.landmarks.push_back(Project(out.camera, p + offset));
  if (!images) return out;

  raytrace::Scene scene;
  raytrace::Material material;
  material.albedo = look.skin;
  scene.AddObject(std::move(mesh), material,
                  raytrace::Transform{raytrace::Mat3::Identity(), {0, 0, kHeadDistanceM}}, 1);
  scene.Commit();
  // Uniform radiance L: sh[0] = L / Y00 = L sqrt(4 pi).
  const float ambient_sh = static_cast<float>(options.ambient * std::sqrt(4 * std::numbers::pi));
  scene.environment().sh[0] = {ambient_sh, ambient_sh, ambient_sh};
  raytrace::ThreadPool pool(options.threads);
  raytrace::RenderOptions render_options;
  render_options.shadows = options.shadows;
  const std::vector<YaleBLightDirection> lights = LightsOf(options);
  const float irradiance = static_cast<float>(options.light_level * std::numbers::pi);
  const auto render = [&](const Vec3& direction, const Vec3& color, bool on) {
    scene.directional_lights() = {{direction, color * irradiance, on}};
    return raytrace::Render(scene, out.camera, render_options, &pool).linear_rgb;
  };
  images->clear();
  for (int pass = 0; pass < (options.rgb ? 2 : 1); ++pass) {
    for (size_t k = 0; k < lights.size(); ++k) {
      YaleBStyleImage image;
      image.light = lights[k];
      image.channels = pass == 0 ? 1 : 3;
      image.file_name = YaleBFileName(subject, lights[k], pass == 0 ? "pgm" : "ppm");
      image.light_color = pass == 0 ? Vec3{1, 1, 1} : LightColor(options.seed, subject, k);
      image.pixels =
          ToBytes(render(LightDirectionFromYaleB(lights[k].azimuth_deg, lights[k].elevation_deg),
                         image.light_color, true),
                  image.channels);
      images->push_back(std::move(image));
    }
  }
  YaleBStyleImage ambient;
  ambient.file_name = Format("yaleB%02d_P00_Ambient.pgm", subject);
  ambient.light_color = {0, 0, 0};
  ambient.pixels = ToBytes(render({0, 0, -1}, {0, 0, 0}, false), 1);
  images->push_back(std::move(ambient));
  return out;
}

YaleBStyleSummary WriteYaleBStyleDataset(const std::string& out_dir,
                                         const YaleBStyleOptions& options) {
  options.Validate();
  const std::vector<YaleBLightDirection> lights = LightsOf(options);
  const uint64_t per_subject = lights.size() * (options.rgb ? 2 : 1) + 1;
  const uint64_t total = per_subject * options.subjects;
  std::error_code error;
  fs::create_directories(out_dir, error);
  if (error || !fs::is_directory(out_dir)) Fail(out_dir + ": cannot create the output folder");

  YaleBStyleSummary summary;
  std::string subjects_json;
  for (int s = 0; s < options.subjects; ++s) {
    const int subject = options.first_subject + s;
    std::vector<YaleBStyleImage> images;
    const YaleBStyleSubject info = RenderYaleBStyleSubject(options, subject, &images);
    const fs::path folder = fs::path(out_dir) / Format("yaleB%02d", subject);
    fs::create_directories(folder, error);
    std::string sidecar =
        "# file azimuth_deg elevation_deg dx dy dz r g b  (direction towards the light, light "
        "frame x = subject's left, y = chin, z = into the head; linear RGB light colour)\n";
    for (const YaleBStyleImage& image : images) {
      const std::string header = Format("%s\n%d %d\n255\n", image.channels == 1 ? "P5" : "P6",
                                        options.width, options.height);
      WriteBinary(folder / image.file_name, header, image.pixels);
      if (image.file_name.find("Ambient") == std::string::npos) {
        const Vec3 d = LightDirectionFromYaleB(image.light.azimuth_deg, image.light.elevation_deg);
        sidecar +=
            Format("%s %d %d %.6f %.6f %.6f %.6f %.6f %.6f\n", image.file_name.c_str(),
                   image.light.azimuth_deg, image.light.elevation_deg, d.x + 0.0f, d.y + 0.0f,
                   d.z + 0.0f, image.light_color.x, image.light_color.y, image.light_color.z);
      }
      ++summary.images;
      if (options.progress) options.progress(summary.images, total);
    }
    std::vector<uint8_t> sidecar_bytes(sidecar.begin(), sidecar.end());
    WriteBinary(folder / Format("yaleB%02d_P00_lights.txt", subject), "", sidecar_bytes);
    summary.max_alignment_error_px =
        std::max(summary.max_alignment_error_px, info.alignment_error_px);
    std::string points;
    for (const Pixel& p : info.aligned_points) {
      points += Format("%s[%.3f, %.3f]", points.empty() ? "" : ", ", p.x, p.y);
    }
    subjects_json += Format(
        "%s    {\"subject\": %d, \"skin\": [%.4f, %.4f, %.4f], \"shape_scale\": [%.4f, %.4f, "
        "%.4f], \"blotches\": %d,\n",
        subjects_json.empty() ? "" : ",\n", subject, info.skin.x, info.skin.y, info.skin.z,
        info.shape_scale.x, info.shape_scale.y, info.shape_scale.z, info.blotches);
    subjects_json += Format("     \"camera\": {\"fx\": %.4f, \"fy\": %.4f, \"cx\": %.4f, ",
                            info.camera.fx, info.camera.fy, info.camera.cx);
    subjects_json += Format("\"cy\": %.4f}, \"alignment_error_px\": %.4f,\n", info.camera.cy,
                            info.alignment_error_px);
    subjects_json += "     \"aligned_points\": [" + points + "]}";
    ++summary.subjects;
  }
  std::string json = "{\n  \"generator\": \"probeless sim --yaleb-style\",\n";
  json += Format("  \"seed\": %llu,\n  \"mesh\": \"%s\",\n  \"width\": %d,\n  \"height\": %d,\n",
                 static_cast<unsigned long long>(options.seed), options.mesh.c_str(), options.width,
                 options.height);
  json += Format("  \"rgb\": %s,\n  \"behind\": %s,\n  \"lights\": %zu,\n",
                 options.rgb ? "true" : "false", options.behind ? "true" : "false", lights.size());
  json += Format("  \"light_level\": %.4f,\n  \"ambient\": %.4f,\n  \"shadows\": %s,\n",
                 options.light_level, options.ambient, options.shadows ? "true" : "false");
  json +=
      "  \"pixels\": \"8-bit, linear in radiance (no sRGB curve); .pgm = Rec. 709 luminance under "
      "a white light\",\n";
  json += "  \"canonical_points\": [[32, 44], [133, 44], [83, 95], [83, 147]],\n";
  json += "  \"subjects\": [\n" + subjects_json + "\n  ]\n}\n";
  WriteBinary(fs::path(out_dir) / "yaleb_style.json", "",
              std::vector<uint8_t>(json.begin(), json.end()));
  return summary;
}

}  // namespace probeless::sim
