#include "probeless/eval/scene_folder.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>

#include "probeless/parse/number.h"

namespace probeless::eval {

namespace {

// A field's location for messages: "<display>:<line>: <field>: ".
struct Where {
  const std::string& display;
  std::string field;
  [[noreturn]] void Fail(const YAML::Node& node, const std::string& problem) const {
    const int line = node.Mark().line >= 0 ? node.Mark().line + 1 : 1;
    throw EvalError(display + ":" + std::to_string(line) + ": " + field + ": " + problem);
  }
};

std::string Text(const YAML::Node& node) {
  if (node.IsScalar()) return node.Scalar();
  if (node.IsNull()) return "null";
  if (node.IsSequence()) return "a list";
  return "a mapping";
}

YAML::Node LoadFile(const std::string& path, const std::string& display) {
  std::ifstream in(path);
  if (!in) throw EvalError(display + ": cannot open");
  std::stringstream text;
  text << in.rdbuf();
  try {
    return YAML::Load(text.str());
  } catch (const YAML::ParserException& e) {
    throw EvalError(display + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg);
  }
}

// A finite number, or nullopt (text that is not entirely a number).
std::optional<double> Number(const YAML::Node& node) {
  if (!node.IsScalar()) return std::nullopt;
  // parse::'s rules: strtod also took " 1", "0x10" and a trailing newline of a block scalar.
  return parse::TryParseDouble(node.Scalar());
}

double PositiveNumber(const YAML::Node& node, const Where& where) {
  const std::optional<double> v = Number(node);
  if (!v || !(*v > 0)) where.Fail(node, "expected a positive number, got '" + Text(node) + "'");
  return *v;
}

template <size_t N>
std::array<double, N> Numbers(const YAML::Node& node, const Where& where, const char* shape,
                              double min = -HUGE_VAL, double max = HUGE_VAL,
                              const char* range = "") {
  if (!node.IsSequence() || node.size() != N) {
    where.Fail(node, std::string("expected ") + shape + ", got " +
                         (node.IsSequence() ? std::to_string(node.size()) + " values"
                                            : "'" + Text(node) + "'"));
  }
  std::array<double, N> out{};
  for (size_t i = 0; i < N; ++i) {
    const std::optional<double> v = Number(node[i]);
    if (!v || *v < min || *v > max) {
      where.Fail(node[i], std::string("expected ") + shape + range + ", got '" + Text(node[i]) +
                              "' at index " + std::to_string(i));
    }
    out[i] = *v;
  }
  return out;
}

}  // namespace

double InsertedObject::BoundingRadius() const {
  if (shape == Shape::kSphere) return radius;
  return 0.5 * std::sqrt(size[0] * size[0] + size[1] * size[1] + size[2] * size[2]);
}

std::vector<InsertedObject> LoadInsertion(const std::string& path, const std::string& display) {
  const YAML::Node root = LoadFile(path, display);
  if (!root.IsMap()) {
    throw EvalError(display + ":1: expected a mapping with 'objects' (a list of objects)");
  }
  const YAML::Node objects = root["objects"];
  if (!objects) throw EvalError(display + ":1: objects: missing (expected a list of objects)");
  if (!objects.IsSequence() || objects.size() == 0) {
    Where{display, "objects"}.Fail(
        objects, "expected a non-empty list of objects, got '" + Text(objects) + "'");
  }
  std::vector<InsertedObject> out;
  for (size_t i = 0; i < objects.size(); ++i) {
    const YAML::Node o = objects[i];
    const std::string prefix = "objects[" + std::to_string(i) + "]";
    if (!o.IsMap()) Where{display, prefix}.Fail(o, "expected a mapping, got '" + Text(o) + "'");
    auto field = [&](const char* name) { return Where{display, prefix + "." + name}; };
    auto required = [&](const char* name) {
      const YAML::Node n = o[name];
      if (!n) field(name).Fail(o, "missing");
      return n;
    };
    InsertedObject object;
    const YAML::Node shape = required("shape");
    const std::string shape_text = shape.IsScalar() ? shape.Scalar() : Text(shape);
    if (shape_text == "sphere") {
      object.shape = Shape::kSphere;
      object.radius = PositiveNumber(required("radius"), field("radius"));
    } else if (shape_text == "box") {
      object.shape = Shape::kBox;
      object.size =
          Numbers<3>(required("size"), field("size"), "3 positive numbers [x, y, z] m", 1e-9);
    } else {
      field("shape").Fail(shape, "expected sphere or box, got '" + shape_text + "'");
    }
    if (const YAML::Node albedo = o["albedo"]) {
      object.albedo =
          Numbers<3>(albedo, field("albedo"), "3 numbers [r, g, b]", 0, 1, " in [0, 1]");
    }
    object.position = Numbers<3>(required("position"), field("position"), "3 numbers [x, y, z] m");
    if (const YAML::Node rotation = o["rotation"]) {
      object.rotation = Numbers<4>(rotation, field("rotation"), "4 numbers [qx, qy, qz, qw]");
      double n = 0;
      for (double q : object.rotation) n += q * q;
      n = std::sqrt(n);
      if (!(n > 1e-9)) field("rotation").Fail(rotation, "expected a non-zero quaternion");
      for (double& q : object.rotation) q /= n;
    }
    out.push_back(object);
  }
  return out;
}

const TruthFrame* Truth::Find(int64_t stamp_ns) const {
  for (const TruthFrame& f : frames) {
    if (ParseStampNs(f.timestamp) == stamp_ns) return &f;
  }
  return nullptr;
}

Truth LoadTruth(const std::string& path, const std::string& display) {
  const YAML::Node root = LoadFile(path, display);
  if (!root.IsMap()) throw EvalError(display + ":1: expected a JSON object with 'frames'");
  Truth truth;
  if (const YAML::Node type = root["light_type"]; type && type.IsScalar()) {
    truth.light_type = type.Scalar();
  }
  const YAML::Node frames = root["frames"];
  if (!frames) throw EvalError(display + ":1: frames: missing (expected a list of frames)");
  if (!frames.IsSequence()) {
    Where{display, "frames"}.Fail(frames, "expected a list, got '" + Text(frames) + "'");
  }
  for (size_t i = 0; i < frames.size(); ++i) {
    const YAML::Node f = frames[i];
    const std::string prefix = "frames[" + std::to_string(i) + "]";
    if (!f.IsMap()) Where{display, prefix}.Fail(f, "expected an object, got '" + Text(f) + "'");
    auto field = [&](const char* name) { return Where{display, prefix + "." + name}; };
    TruthFrame frame;
    const YAML::Node stamp = f["timestamp"];
    if (!stamp || !stamp.IsScalar() || !ParseStampNs(stamp.Scalar())) {
      field("timestamp")
          .Fail(stamp ? stamp : f, "expected a time stamp as in rgb.txt, got '" +
                                       (stamp ? Text(stamp) : "nothing") + "'");
    }
    frame.timestamp = stamp.Scalar();
    if (const YAML::Node d = f["direction_camera"]; d && !d.IsNull()) {
      frame.direction_camera = Numbers<3>(d, field("direction_camera"), "3 numbers or null");
    }
    if (const YAML::Node r = f["direct_to_ambient"]; r && !r.IsNull()) {
      const std::optional<double> v = Number(r);
      if (!v || *v < 0) {
        field("direct_to_ambient").Fail(r, "expected a number >= 0, got '" + Text(r) + "'");
      }
      frame.direct_to_ambient = *v;
    }
    if (const YAML::Node sh = f["sh_camera"]; sh && !sh.IsNull()) {
      if (!sh.IsSequence() || sh.size() != 9) {
        field("sh_camera")
            .Fail(sh, "expected 9 [r, g, b] coefficients, got " +
                          (sh.IsSequence() ? std::to_string(sh.size()) : "'" + Text(sh) + "'"));
      }
      std::array<std::array<double, 3>, 9> coefficients{};
      for (size_t k = 0; k < 9; ++k) {
        coefficients[k] =
            Numbers<3>(sh[k], Where{display, prefix + ".sh_camera[" + std::to_string(k) + "]"},
                       "3 numbers [r, g, b]");
      }
      frame.sh_camera = coefficients;
    }
    truth.frames.push_back(std::move(frame));
  }
  return truth;
}

std::optional<int64_t> ParseStampNs(const std::string& text) {
  size_t i = 0;
  int64_t seconds = 0;
  if (text.empty()) return std::nullopt;
  // The largest whole second whose nanosecond count (plus a fraction) still fits in int64.
  constexpr int64_t kMaxSeconds = std::numeric_limits<int64_t>::max() / 1'000'000'000LL - 1;
  while (i < text.size() && text[i] >= '0' && text[i] <= '9') {
    seconds = seconds * 10 + (text[i] - '0');
    if (seconds > kMaxSeconds) return std::nullopt;
    ++i;
  }
  if (i == 0) return std::nullopt;
  int64_t nanos = 0;
  if (i < text.size()) {
    if (text[i] != '.') return std::nullopt;
    ++i;
    int digits = 0;
    for (; i < text.size(); ++i, ++digits) {
      if (text[i] < '0' || text[i] > '9') return std::nullopt;
      if (digits < 9) nanos = nanos * 10 + (text[i] - '0');
    }
    for (; digits < 9; ++digits) nanos *= 10;
  }
  return seconds * 1'000'000'000LL + nanos;
}

std::vector<RgbEntry> LoadRgbList(const std::string& path, const std::string& display) {
  std::ifstream in(path);
  if (!in) throw EvalError(display + ": cannot open");
  std::vector<RgbEntry> entries;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const size_t first = line.find_first_not_of(" \t");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream words(line);
    RgbEntry e;
    std::string extra;
    if (!(words >> e.timestamp >> e.file) || (words >> extra)) {
      throw EvalError(display + ":" + std::to_string(number) +
                      ": expected 'timestamp filename', got '" + line + "'");
    }
    const std::optional<int64_t> ns = ParseStampNs(e.timestamp);
    if (!ns) {
      throw EvalError(display + ":" + std::to_string(number) + ": malformed time stamp '" +
                      e.timestamp + "'");
    }
    e.stamp_ns = *ns;
    entries.push_back(std::move(e));
  }
  std::stable_sort(entries.begin(), entries.end(),
                   [](const RgbEntry& a, const RgbEntry& b) { return a.stamp_ns < b.stamp_ns; });
  return entries;
}

}  // namespace probeless::eval
