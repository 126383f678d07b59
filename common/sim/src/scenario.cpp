#include "probeless/sim/scenario.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <set>
#include <sstream>

namespace probeless::sim {
namespace {

namespace fs = std::filesystem;

class Parser {
 public:
  Parser(std::string file, std::string base_dir)
      : file_(std::move(file)), base_(std::move(base_dir)) {}

  [[noreturn]] void Fail(const YAML::Node& node, const std::string& field,
                         const std::string& what) const {
    const YAML::Mark mark = node.Mark();
    const int line = mark.is_null() ? 0 : mark.line + 1;
    throw ScenarioError(file_ + ":" + std::to_string(line) + ": " + field + ": " + what);
  }

  void CheckMap(const YAML::Node& node, const std::string& field) const {
    if (!node.IsMap()) Fail(node, field, "expected a mapping");
  }

  void CheckKeys(const YAML::Node& node, const std::string& field,
                 const std::set<std::string>& allowed) const {
    CheckMap(node, field);
    for (const auto& kv : node) {
      const std::string key = kv.first.as<std::string>();
      if (!allowed.contains(key)) {
        std::string list;
        for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
        Fail(kv.first, field.empty() ? key : field + "." + key,
             "unknown key (expected one of " + list + ")");
      }
    }
  }

  static std::string Join(const std::string& field, const std::string& key) {
    return field.empty() ? key : field + "." + key;
  }

  double Number(const YAML::Node& n, const std::string& field) const {
    if (!n.IsScalar()) Fail(n, field, "expected a number");
    try {
      const double v = n.as<double>();
      if (!std::isfinite(v)) Fail(n, field, "expected a finite number");
      return v;
    } catch (const YAML::Exception&) {
      Fail(n, field, "expected a number, got '" + n.Scalar() + "'");
    }
  }
  double Number(const YAML::Node& map, const std::string& field, const char* key, double def,
                double lo = -1e300, double hi = 1e300) const {
    const YAML::Node n = map[key];
    if (!n) return def;
    const double v = Number(n, Join(field, key));
    if (v < lo || v > hi) {
      std::ostringstream range;
      range << "value " << v << " out of range [" << lo << ", " << hi << "]";
      Fail(n, Join(field, key), range.str());
    }
    return v;
  }
  bool Bool(const YAML::Node& map, const std::string& field, const char* key, bool def) const {
    const YAML::Node n = map[key];
    if (!n) return def;
    try {
      if (!n.IsScalar()) throw YAML::Exception(YAML::Mark(), "");
      return n.as<bool>();
    } catch (const YAML::Exception&) {
      Fail(n, Join(field, key), "expected true or false");
    }
  }
  std::string String(const YAML::Node& map, const std::string& field, const char* key,
                     const std::string& def) const {
    const YAML::Node n = map[key];
    if (!n) return def;
    if (!n.IsScalar()) Fail(n, Join(field, key), "expected a string");
    return n.Scalar();
  }
  Vec3d Vector(const YAML::Node& n, const std::string& field) const {
    if (!n.IsSequence() || n.size() != 3) Fail(n, field, "expected a list of 3 numbers");
    Vec3d v;
    for (size_t i = 0; i < 3; ++i) v[i] = Number(n[i], field);
    return v;
  }
  Vec3d Vector(const YAML::Node& map, const std::string& field, const char* key,
               const Vec3d& def) const {
    const YAML::Node n = map[key];
    return n ? Vector(n, Join(field, key)) : def;
  }
  // A file name: "data:REL" or relative to the scenario's folder. Throws unless it exists (when
  // `must_exist`); returns "" for a missing optional file.
  std::string File(const YAML::Node& n, const std::string& field, bool must_exist) const {
    if (!n.IsScalar()) Fail(n, field, "expected a file name");
    const std::string name = n.Scalar();
    std::string resolved;
    if (name.starts_with("data:")) {
      const std::optional<std::string> found = FindDataFile(name.substr(5));
      if (found) return *found;
      if (!must_exist) return "";
      Fail(n, field,
           "data file '" + name.substr(5) +
               "' not found in $PROBELESS_DATA or the shared data folder");
    }
    resolved = fs::path(name).is_absolute() ? name : (fs::path(base_) / name).string();
    std::error_code error;
    if (!fs::is_regular_file(resolved, error)) {
      if (!must_exist) return "";
      Fail(n, field, "file '" + resolved + "' not found");
    }
    return resolved;
  }

  std::vector<PoseKey> PoseKeys(const YAML::Node& n, const std::string& field, bool camera) const {
    if (!n.IsSequence() || n.size() == 0) Fail(n, field, "expected a non-empty list of keyframes");
    std::vector<PoseKey> keys;
    for (size_t i = 0; i < n.size(); ++i) {
      const std::string f = field + "[" + std::to_string(i) + "]";
      CheckKeys(n[i], f, {"t", "position", "look_at", "up", "rotation_deg"});
      PoseKey k;
      k.t = Number(n[i], f, "t", 0);
      if (!n[i]["position"]) Fail(n[i], f, "missing 'position'");
      k.position = Vector(n[i], f, "position", {});
      if (n[i]["look_at"]) k.look_at = Vector(n[i], f, "look_at", {});
      k.up = Vector(n[i], f, "up", {0, 1, 0});
      k.rotation_deg = Vector(n[i], f, "rotation_deg", {0, 0, 0});
      if (camera && !k.look_at && !n[i]["rotation_deg"]) {
        Fail(n[i], f, "a camera keyframe needs 'look_at' or 'rotation_deg'");
      }
      if (!keys.empty() && !(k.t > keys.back().t)) {
        Fail(n[i], Join(f, "t"), "keyframe times must increase");
      }
      keys.push_back(k);
    }
    return keys;
  }

  Scenario Parse(const YAML::Node& root) const {
    Scenario s;
    s.path = file_;
    CheckKeys(root, "",
              {"name", "seed", "fps", "frames", "camera", "render", "sensor", "environment",
               "objects", "lights", "ground_truth"});
    s.name = String(root, "", "name", fs::path(file_).stem().string());
    s.seed = static_cast<uint64_t>(Number(root, "", "seed", 1, 0, 9.0e15));
    s.fps = Number(root, "", "fps", 30, 0.1, 1000);
    s.frames = static_cast<uint64_t>(Number(root, "", "frames", 90, 1, 1e7));

    const YAML::Node camera = root["camera"];
    if (!camera) Fail(root, "camera", "missing (a camera with a path is required)");
    CheckKeys(camera, "camera", {"width", "height", "fx", "fy", "cx", "cy", "path", "frame_id"});
    CameraSpec& c = s.camera;
    c.width = static_cast<int>(Number(camera, "camera", "width", 640, 1, 16384));
    c.height = static_cast<int>(Number(camera, "camera", "height", 480, 1, 16384));
    c.fx = Number(camera, "camera", "fx", 525.0 * c.width / 640, 1e-6);
    c.fy = Number(camera, "camera", "fy", c.fx, 1e-6);
    c.cx = Number(camera, "camera", "cx", (c.width - 1) / 2.0);
    c.cy = Number(camera, "camera", "cy", (c.height - 1) / 2.0);
    s.camera_frame_id = String(camera, "camera", "frame_id", "camera");
    if (s.camera_frame_id.empty() || s.camera_frame_id.size() > 31) {
      Fail(camera["frame_id"], "camera.frame_id", "must have 1 to 31 characters");
    }
    if (!camera["path"]) Fail(camera, "camera.path", "missing (at least one keyframe)");
    c.path = PoseKeys(camera["path"], "camera.path", true);

    if (const YAML::Node r = root["render"]) {
      CheckKeys(r, "render", {"shadows", "diffuse_bounce", "bounce_samples"});
      s.render.shadows = Bool(r, "render", "shadows", true);
      s.render.diffuse_bounce = Bool(r, "render", "diffuse_bounce", false);
      s.render.bounce_samples = static_cast<int>(Number(r, "render", "bounce_samples", 2, 1, 256));
    }
    if (const YAML::Node n = root["sensor"]) {
      CheckKeys(
          n, "sensor",
          {"depth_min", "depth_max", "depth_noise", "depth_noise_a", "depth_noise_b", "depth_holes",
           "edge_ratio", "dropout", "quantisation", "color_noise", "exposure", "auto_exposure"});
      SensorSpec& e = s.sensor;
      e.depth_min_m = Number(n, "sensor", "depth_min", 0.4, 0, 65);
      e.depth_max_m = Number(n, "sensor", "depth_max", 8, 0, 65.535);
      e.depth_noise = Bool(n, "sensor", "depth_noise", false);
      e.depth_noise_a = Number(n, "sensor", "depth_noise_a", 0.0012, 0, 1);
      e.depth_noise_b = Number(n, "sensor", "depth_noise_b", 0.0019, 0, 1);
      e.depth_holes = Bool(n, "sensor", "depth_holes", false);
      e.edge_ratio = Number(n, "sensor", "edge_ratio", 0.04, 0, 10);
      e.dropout = Number(n, "sensor", "dropout", 0, 0, 1);
      e.quantisation = Number(n, "sensor", "quantisation", 0, 0, 1);
      e.color_noise = Number(n, "sensor", "color_noise", 0, 0, 1);
      e.exposure = Number(n, "sensor", "exposure", 1, 0, 1e6);
      e.auto_exposure = Bool(n, "sensor", "auto_exposure", false);
    }
    if (const YAML::Node n = root["environment"]) {
      CheckKeys(n, "environment", {"constant", "sky", "ground", "sh", "latlong", "scale"});
      const Vec3d constant = Vector(n, "environment", "constant", {0, 0, 0});
      // Y_00 = 1 / (2 sqrt(pi)): a uniform radiance L has c_0 = 2 sqrt(pi) L.
      const double k0 = 2 * std::sqrt(std::numbers::pi);
      // sky/ground: L(w) = (sky + ground) / 2 + (sky - ground) / 2 * w.y (band 1 exactly);
      // w.y = -Y_1,-1 / sqrt(3 / (4 pi)).
      const Vec3d sky = Vector(n, "environment", "sky", {0, 0, 0});
      const Vec3d ground = Vector(n, "environment", "ground", {0, 0, 0});
      const double k1 = 1 / std::sqrt(3 / (4 * std::numbers::pi));
      for (int ch = 0; ch < 3; ++ch) {
        s.environment_sh[0][ch] = k0 * (constant[ch] + (sky[ch] + ground[ch]) / 2);
        s.environment_sh[1][ch] = -k1 * (sky[ch] - ground[ch]) / 2;
      }
      if (const YAML::Node sh = n["sh"]) {
        if (!sh.IsSequence() || sh.size() > 9) {
          Fail(sh, "environment.sh", "expected a list of up to 9 [r, g, b] coefficients");
        }
        for (size_t i = 0; i < sh.size(); ++i) {
          const Vec3d v = Vector(sh[i], "environment.sh[" + std::to_string(i) + "]");
          for (int ch = 0; ch < 3; ++ch) s.environment_sh[i][ch] += v[ch];
        }
      }
      if (const YAML::Node m = n["latlong"])
        s.environment_map = File(m, "environment.latlong", true);
      s.environment_map_scale = Number(n, "environment", "scale", 1, 0);
    }
    if (const YAML::Node objects = root["objects"]) {
      if (!objects.IsSequence()) Fail(objects, "objects", "expected a list");
      for (size_t i = 0; i < objects.size(); ++i) s.objects.push_back(Object(objects[i], i));
    }
    if (const YAML::Node lights = root["lights"]) {
      if (!lights.IsSequence()) Fail(lights, "lights", "expected a list");
      for (size_t i = 0; i < lights.size(); ++i) s.lights.push_back(Light(lights[i], i));
    }
    if (const YAML::Node g = root["ground_truth"]) {
      CheckKeys(g, "ground_truth", {"face_rate", "light_rate", "world_frame_id"});
      s.face_rate_hz = Number(g, "ground_truth", "face_rate", 0, 0, 1000);
      s.light_rate_hz = Number(g, "ground_truth", "light_rate", 0, 0, 1000);
      s.world_frame_id = String(g, "ground_truth", "world_frame_id", "world");
      if (s.world_frame_id.empty() || s.world_frame_id.size() > 31) {
        Fail(g["world_frame_id"], "ground_truth.world_frame_id", "must have 1 to 31 characters");
      }
    }
    return s;
  }

  ObjectSpec Object(const YAML::Node& n, size_t index) const {
    const std::string f = "objects[" + std::to_string(index) + "]";
    CheckKeys(n, f, {"name",         "shape",    "size",
                     "radius",       "height",   "file",
                     "fallback",     "scale",    "mesh_rotation_deg",
                     "mesh_offset",  "color",    "texture",
                     "uv_repeat",    "specular", "shininess",
                     "id",           "face",     "position",
                     "rotation_deg", "path"});
    ObjectSpec o;
    o.name = String(n, f, "name", "object" + std::to_string(index + 1));
    if (!n["shape"]) Fail(n, f, "missing 'shape' (plane, box, sphere, cylinder, head or mesh)");
    o.shape = String(n, f, "shape", "");
    static const std::set<std::string> kShapes = {"plane",    "box",  "sphere",
                                                  "cylinder", "head", "mesh"};
    if (!kShapes.contains(o.shape)) {
      Fail(n["shape"], Join(f, "shape"),
           "unknown shape '" + o.shape + "' (expected plane, box, sphere, cylinder, head or mesh)");
    }
    o.size = Vector(n, f, "size", {1, 1, 1});
    o.radius = Number(n, f, "radius", 0.5, 1e-6);
    o.height = Number(n, f, "height", 1, 1e-6);
    o.fallback = String(n, f, "fallback", "");
    if (!o.fallback.empty() && o.fallback != "head") {
      Fail(n["fallback"], Join(f, "fallback"), "expected 'head'");
    }
    if (o.shape == "mesh") {
      if (!n["file"]) Fail(n, f, "a mesh needs 'file'");
      o.file = File(n["file"], Join(f, "file"), o.fallback.empty());
    }
    o.scale = Number(n, f, "scale", 1, 1e-9);
    o.mesh_rotation_deg = Vector(n, f, "mesh_rotation_deg", {0, 0, 0});
    o.mesh_offset = Vector(n, f, "mesh_offset", {0, 0, 0});
    o.color = Vector(n, f, "color", {0.7, 0.7, 0.7});
    for (double v : o.color) {
      if (v < 0 || v > 1) Fail(n["color"], Join(f, "color"), "albedo components must be in [0, 1]");
    }
    if (const YAML::Node t = n["texture"]) o.texture = File(t, Join(f, "texture"), true);
    o.uv_repeat = Number(n, f, "uv_repeat", 1, 1e-6);
    o.specular = Number(n, f, "specular", 0, 0, 1);
    o.shininess = Number(n, f, "shininess", 32, 1, 10000);
    o.id = static_cast<uint32_t>(Number(n, f, "id", static_cast<double>(index + 1), 1, 4e9));
    o.face = Bool(n, f, "face", o.shape == "head" || (o.shape == "mesh" && o.fallback == "head"));
    if (n["path"]) {
      if (n["position"] || n["rotation_deg"]) {
        Fail(n["path"], Join(f, "path"), "give either 'path' or 'position'/'rotation_deg'");
      }
      o.path = PoseKeys(n["path"], Join(f, "path"), false);
    } else {
      PoseKey k;
      k.position = Vector(n, f, "position", {0, 0, 0});
      k.rotation_deg = Vector(n, f, "rotation_deg", {0, 0, 0});
      o.path.push_back(k);
    }
    return o;
  }

  LightSpec Light(const YAML::Node& n, size_t index) const {
    const std::string f = "lights[" + std::to_string(index) + "]";
    CheckKeys(
        n, f,
        {"name", "type", "direction", "position", "color", "intensity", "on", "orbit", "path"});
    LightSpec l;
    l.name = String(n, f, "name", "light" + std::to_string(index + 1));
    const std::string type = String(n, f, "type", "");
    if (type != "directional" && type != "point") {
      Fail(n["type"] ? n["type"] : n, Join(f, "type"), "expected 'directional' or 'point'");
    }
    l.directional = type == "directional";
    LightKey base;
    base.direction = Vector(n, f, "direction", {0, 1, 0});
    base.position = Vector(n, f, "position", {0, 2, 0});
    base.color = Vector(n, f, "color", {1, 1, 1});
    base.intensity = Number(n, f, "intensity", l.directional ? std::numbers::pi : 1, 0);
    base.on = Bool(n, f, "on", true);
    if (const YAML::Node o = n["orbit"]) {
      const std::string of = Join(f, "orbit");
      CheckKeys(o, of, {"centre", "radius", "height", "period", "phase_deg"});
      Orbit orbit;
      orbit.centre = Vector(o, of, "centre", {0, 0, 0});
      orbit.radius = Number(o, of, "radius", 1, 0);
      orbit.height = Number(o, of, "height", 0);
      orbit.period_s = Number(o, of, "period", 10, 1e-3);
      orbit.phase_deg = Number(o, of, "phase_deg", 0);
      l.orbit = orbit;
    }
    if (const YAML::Node p = n["path"]) {
      const std::string pf = Join(f, "path");
      if (!p.IsSequence() || p.size() == 0) Fail(p, pf, "expected a non-empty list of keyframes");
      for (size_t i = 0; i < p.size(); ++i) {
        const std::string kf = pf + "[" + std::to_string(i) + "]";
        CheckKeys(p[i], kf, {"t", "direction", "position", "color", "intensity", "on"});
        const LightKey& prev = l.keys.empty() ? base : l.keys.back();
        LightKey k;
        k.t = Number(p[i], kf, "t", 0);
        k.direction = Vector(p[i], kf, "direction", prev.direction);
        k.position = Vector(p[i], kf, "position", prev.position);
        k.color = Vector(p[i], kf, "color", prev.color);
        k.intensity = Number(p[i], kf, "intensity", prev.intensity, 0);
        k.on = Bool(p[i], kf, "on", prev.on);
        if (!l.keys.empty() && !(k.t > l.keys.back().t)) {
          Fail(p[i], Join(kf, "t"), "keyframe times must increase");
        }
        l.keys.push_back(k);
      }
    } else {
      l.keys.push_back(base);
    }
    return l;
  }

 private:
  std::string file_;
  std::string base_;
};

}  // namespace

std::optional<std::string> FindDataFile(const std::string& relative) {
  std::error_code error;
  if (const char* env = std::getenv("PROBELESS_DATA"); env != nullptr && *env != '\0') {
    const fs::path p = fs::path(env) / relative;
    if (fs::is_regular_file(p, error)) return p.string();
  }
  const fs::path p = fs::path(PROBELESS_SIM_SOURCE_DIR) / ".." / "shared" / "data" / relative;
  if (fs::is_regular_file(p, error)) return fs::weakly_canonical(p, error).string();
  return std::nullopt;
}

Scenario ParseScenario(const std::string& yaml, const std::string& name_for_errors,
                       const std::string& base_dir) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml);
  } catch (const YAML::ParserException& e) {
    throw ScenarioError(name_for_errors + ":" + std::to_string(e.mark.line + 1) +
                        ": YAML syntax error: " + e.msg);
  }
  Parser parser(name_for_errors, base_dir);
  if (!root.IsMap()) {
    throw ScenarioError(name_for_errors + ":1: expected a scenario mapping at the top level");
  }
  try {
    return parser.Parse(root);
  } catch (const YAML::Exception& e) {
    throw ScenarioError(name_for_errors + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg);
  }
}

Scenario LoadScenario(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw ScenarioError(path + ": cannot open scenario file");
  std::stringstream text;
  text << in.rdbuf();
  const fs::path parent = fs::path(path).parent_path();
  return ParseScenario(text.str(), path, parent.empty() ? "." : parent.string());
}

}  // namespace probeless::sim
