// OBJ and PLY readers.
#include <algorithm>
#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <tuple>

#include "probeless/parse/number.h"
#include "probeless/raytrace/mesh.h"
#include "probeless/raytrace/render.h"

namespace probeless::raytrace {
namespace {

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// The project's number rules (probeless/parse/number.h): whole token, finite, in range.
bool ParseFloat(std::string_view text, float& out) {
  const auto value = parse::TryParseDouble(text, std::numeric_limits<float>::lowest(),
                                           std::numeric_limits<float>::max());
  if (value) out = static_cast<float>(*value);
  return value.has_value();
}

bool ParseInt(std::string_view text, long long& out) {
  const auto value = parse::TryParseInteger<long long>(text);
  if (value) out = *value;
  return value.has_value();
}

std::vector<std::string_view> SplitWhitespace(std::string_view line) {
  std::vector<std::string_view> out;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    const size_t start = i;
    while (i < line.size() && !std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    if (i > start) out.push_back(line.substr(start, i - start));
  }
  return out;
}

}  // namespace

Mesh LoadObj(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw RaytraceError(path + ": cannot open OBJ file");
  std::vector<Vec3> v;
  std::vector<Vec3> vc;
  bool any_color = false;
  std::vector<Vec2> vt;
  std::vector<Vec3> vn;
  Mesh mesh;
  bool uses_uv = false;
  bool uses_normal = false;
  std::map<std::tuple<long long, long long, long long>, uint32_t> vertex_of;
  std::string line;
  int line_number = 0;
  auto fail = [&](const std::string& what) -> void {
    throw RaytraceError(path + ":" + std::to_string(line_number) + ": " + what);
  };
  std::vector<uint32_t> polygon;
  while (std::getline(in, line)) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const auto tokens = SplitWhitespace(line);
    if (tokens.empty() || tokens[0].front() == '#') continue;
    const std::string_view key = tokens[0];
    auto floats = [&](size_t first, size_t count, float* out) {
      for (size_t k = 0; k < count; ++k) {
        if (!ParseFloat(tokens[first + k], out[k])) {
          fail("expected a number, got '" + std::string(tokens[first + k]) + "'");
        }
      }
    };
    if (key == "v") {
      if (tokens.size() != 4 && tokens.size() != 5 && tokens.size() != 7) {
        fail("vertex 'v' expects 3 coordinates (optionally w, or r g b), got " +
             std::to_string(tokens.size() - 1) + " values");
      }
      float p[3];
      floats(1, 3, p);
      v.push_back({p[0], p[1], p[2]});
      Vec3 color{1, 1, 1};
      if (tokens.size() == 7) {
        float c[3];
        floats(4, 3, c);
        color = {c[0], c[1], c[2]};
        any_color = true;
      }
      vc.push_back(color);
    } else if (key == "vt") {
      if (tokens.size() < 2 || tokens.size() > 4) {
        fail("texture coordinate 'vt' expects 1 to 3 values, got " +
             std::to_string(tokens.size() - 1));
      }
      float t[2] = {0, 0};
      floats(1, std::min<size_t>(2, tokens.size() - 1), t);
      vt.push_back({t[0], t[1]});
    } else if (key == "vn") {
      if (tokens.size() != 4) {
        fail("normal 'vn' expects 3 values, got " + std::to_string(tokens.size() - 1));
      }
      float n[3];
      floats(1, 3, n);
      vn.push_back(Normalize({n[0], n[1], n[2]}));
    } else if (key == "f") {
      if (tokens.size() < 4) {
        fail("face 'f' expects at least 3 vertices, got " + std::to_string(tokens.size() - 1));
      }
      polygon.clear();
      for (size_t k = 1; k < tokens.size(); ++k) {
        long long idx[3] = {0, 0, 0};
        std::string_view rest = tokens[k];
        for (int part = 0; part < 3; ++part) {
          const size_t slash = rest.find('/');
          const std::string_view field = rest.substr(0, slash);
          if (!field.empty()) {
            if (!ParseInt(field, idx[part]) || idx[part] == 0) {
              fail("malformed face vertex '" + std::string(tokens[k]) + "'");
            }
          } else if (part == 0) {
            fail("malformed face vertex '" + std::string(tokens[k]) + "'");
          }
          if (slash == std::string_view::npos) break;
          rest = rest.substr(slash + 1);
          if (part == 2) fail("malformed face vertex '" + std::string(tokens[k]) + "'");
        }
        const long long sizes[3] = {static_cast<long long>(v.size()),
                                    static_cast<long long>(vt.size()),
                                    static_cast<long long>(vn.size())};
        const char* names[3] = {"vertex", "texture coordinate", "normal"};
        for (int part = 0; part < 3; ++part) {
          // 0 means "not given"; a relative index that resolves to 0 or below is out of range (it
          // was taken as "not given", and for the vertex read v[-1]; found by mesh_fuzz).
          const long long written = idx[part];
          if (idx[part] < 0) idx[part] += sizes[part] + 1;
          if (written != 0 && (idx[part] < 1 || idx[part] > sizes[part])) {
            fail(std::string(names[part]) + " index " + std::to_string(written) +
                 " out of range (" + std::to_string(sizes[part]) + " defined so far)");
          }
        }
        uses_uv = uses_uv || idx[1] != 0;
        uses_normal = uses_normal || idx[2] != 0;
        const auto key3 = std::make_tuple(idx[0], idx[1], idx[2]);
        auto it = vertex_of.find(key3);
        if (it == vertex_of.end()) {
          const uint32_t id = static_cast<uint32_t>(mesh.positions.size());
          mesh.positions.push_back(v[idx[0] - 1]);
          mesh.colors.push_back(vc[idx[0] - 1]);
          mesh.uvs.push_back(idx[1] ? vt[idx[1] - 1] : Vec2{});
          mesh.normals.push_back(idx[2] ? vn[idx[2] - 1] : Vec3{});
          it = vertex_of.emplace(key3, id).first;
        }
        polygon.push_back(it->second);
      }
      for (size_t k = 1; k + 1 < polygon.size(); ++k) {
        mesh.triangles.push_back({polygon[0], polygon[k], polygon[k + 1]});
      }
    } else if (key == "o" || key == "g" || key == "s" || key == "usemtl" || key == "mtllib" ||
               key == "l" || key == "p" || key == "vp") {
      continue;
    } else {
      fail("unknown OBJ statement '" + std::string(key) + "'");
    }
  }
  if (in.bad()) throw RaytraceError(path + ": read error");
  if (mesh.triangles.empty()) throw RaytraceError(path + ": OBJ file has no faces");
  if (!any_color) mesh.colors.clear();
  if (!uses_uv) mesh.uvs.clear();
  // Vertices without a normal get computed ones.
  const bool all_normals = uses_normal && std::none_of(mesh.normals.begin(), mesh.normals.end(),
                                                       [](Vec3 n) { return Length(n) == 0; });
  if (!all_normals) mesh.ComputeNormals();
  return mesh;
}

namespace {

enum class PlyFormat { kAscii, kBinaryLittle, kBinaryBig };

struct PlyProperty {
  std::string name;
  std::string type;        // scalar type, or the item type of a list
  std::string count_type;  // non-empty for a list
};

struct PlyElement {
  std::string name;
  size_t count = 0;
  std::vector<PlyProperty> properties;
};

size_t PlyTypeSize(const std::string& type) {
  if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "int32" || type == "uint32" || type == "float" ||
      type == "float32")
    return 4;
  if (type == "double" || type == "float64") return 8;
  return 0;
}

class PlyReader {
 public:
  PlyReader(std::istream& in, PlyFormat format, const std::string& path)
      : in_(in), format_(format), path_(path) {}

  double Read(const std::string& type, const std::string& element) {
    if (format_ == PlyFormat::kAscii) {
      std::string token;
      if (!(in_ >> token)) Fail(element, "unexpected end of file");
      const auto value = parse::TryParseDouble(token);
      if (!value) Fail(element, "expected a number, got '" + token + "'");
      return *value;
    }
    const size_t size = PlyTypeSize(type);
    unsigned char bytes[8];
    if (!in_.read(reinterpret_cast<char*>(bytes), static_cast<std::streamsize>(size))) {
      Fail(element, "unexpected end of file");
    }
    const bool swap =
        (format_ == PlyFormat::kBinaryBig) == (std::endian::native == std::endian::little);
    if (swap) std::reverse(bytes, bytes + size);
    auto as = [&](auto value) {
      std::memcpy(&value, bytes, sizeof(value));
      return static_cast<double>(value);
    };
    if (type == "char" || type == "int8") return as(int8_t{});
    if (type == "uchar" || type == "uint8") return as(uint8_t{});
    if (type == "short" || type == "int16") return as(int16_t{});
    if (type == "ushort" || type == "uint16") return as(uint16_t{});
    if (type == "int" || type == "int32") return as(int32_t{});
    if (type == "uint" || type == "uint32") return as(uint32_t{});
    if (type == "float" || type == "float32") return as(float{});
    return as(double{});
  }

  // A list count or a vertex index: a non-negative integer below 2^32 whatever the property's
  // type (a float 1.5 or a NaN from a binary file was cast to an index before, issue #22).
  uint32_t ReadIndex(const std::string& type, const std::string& element, const std::string& what) {
    const double value = Read(type, element);
    if (!(value >= 0 && value <= std::numeric_limits<uint32_t>::max()) ||
        value != std::floor(value)) {
      char text[32];
      std::snprintf(text, sizeof(text), "%.17g", value);
      Fail(element, what + " must be a non-negative integer, got " + text);
    }
    return static_cast<uint32_t>(value);
  }

  [[noreturn]] void Fail(const std::string& element, const std::string& what) {
    throw RaytraceError(path_ + ": element " + element + ": " + what);
  }

 private:
  std::istream& in_;
  PlyFormat format_;
  const std::string& path_;
};

}  // namespace

Mesh LoadPly(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw RaytraceError(path + ": cannot open PLY file");
  std::string line;
  int line_number = 0;
  auto fail = [&](const std::string& what) -> void {
    throw RaytraceError(path + ":" + std::to_string(line_number) + ": " + what);
  };
  auto next_line = [&]() -> bool {
    if (!std::getline(in, line)) return false;
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return true;
  };
  if (!next_line() || line != "ply") {
    line_number = 1;
    fail("not a PLY file (expected 'ply' on the first line)");
  }
  std::vector<PlyElement> elements;
  std::optional<PlyFormat> format;
  bool ended = false;
  while (next_line()) {
    const auto tokens = SplitWhitespace(line);
    if (tokens.empty()) continue;
    if (tokens[0] == "comment" || tokens[0] == "obj_info") continue;
    if (tokens[0] == "format") {
      if (tokens.size() != 3)
        fail("expected 'format <ascii|binary_little_endian|binary_big_endian> 1.0'");
      if (tokens[1] == "ascii") {
        format = PlyFormat::kAscii;
      } else if (tokens[1] == "binary_little_endian") {
        format = PlyFormat::kBinaryLittle;
      } else if (tokens[1] == "binary_big_endian") {
        format = PlyFormat::kBinaryBig;
      } else {
        fail("unknown PLY format '" + std::string(tokens[1]) + "'");
      }
    } else if (tokens[0] == "element") {
      long long count = 0;
      if (tokens.size() != 3 || !ParseInt(tokens[2], count) || count < 0) {
        fail("expected 'element <name> <count>'");
      }
      elements.push_back({std::string(tokens[1]), static_cast<size_t>(count), {}});
    } else if (tokens[0] == "property") {
      if (elements.empty()) fail("property before any element");
      PlyProperty p;
      if (tokens.size() == 5 && tokens[1] == "list") {
        p.count_type = std::string(tokens[2]);
        p.type = std::string(tokens[3]);
        p.name = std::string(tokens[4]);
        if (PlyTypeSize(p.count_type) == 0) fail("unknown PLY type '" + p.count_type + "'");
      } else if (tokens.size() == 3) {
        p.type = std::string(tokens[1]);
        p.name = std::string(tokens[2]);
      } else {
        fail("expected 'property <type> <name>' or 'property list <count type> <type> <name>'");
      }
      if (PlyTypeSize(p.type) == 0) fail("unknown PLY type '" + p.type + "'");
      elements.back().properties.push_back(p);
    } else if (tokens[0] == "end_header") {
      ended = true;
      break;
    } else {
      fail("unknown PLY header line '" + line + "'");
    }
  }
  if (!ended) fail("missing 'end_header'");
  if (!format) throw RaytraceError(path + ": PLY header has no 'format' line");
  // Header counts against the body's size before anything is read or allocated: each entry takes
  // at least one byte per scalar (one digit per token in ASCII), so a 100-byte file cannot ask for
  // 2^40 vertices, and an element without properties (which would read nothing per entry) must be
  // empty.
  const std::streampos body_start = in.tellg();
  in.seekg(0, std::ios::end);
  const uint64_t body_bytes = static_cast<uint64_t>(in.tellg() - body_start);
  in.seekg(body_start);
  for (const PlyElement& e : elements) {
    uint64_t min_bytes = 0;
    for (const PlyProperty& p : e.properties) {
      min_bytes += *format == PlyFormat::kAscii
                       ? 1
                       : PlyTypeSize(p.count_type.empty() ? p.type : p.count_type);
    }
    if (e.count > 0 && min_bytes == 0) {
      throw RaytraceError(path + ": element " + e.name + " has " + std::to_string(e.count) +
                          " entries but no properties");
    }
    if (min_bytes > 0 && e.count > body_bytes / min_bytes) {
      throw RaytraceError(path + ": element " + e.name + " has " + std::to_string(e.count) +
                          " entries of at least " + std::to_string(min_bytes) +
                          " bytes, but the file has " + std::to_string(body_bytes) +
                          " bytes after the header (truncated or a wrong count)");
    }
  }
  PlyReader reader(in, *format, path);
  Mesh mesh;
  bool has_vertex = false;
  bool has_face = false;
  bool has_normals = false;
  bool has_colors = false;
  bool has_uvs = false;
  for (const PlyElement& e : elements) {
    if (e.name == "vertex") {
      has_vertex = true;
      std::map<std::string, size_t> index;
      for (size_t k = 0; k < e.properties.size(); ++k) {
        if (!e.properties[k].count_type.empty()) {
          reader.Fail("vertex", "list property '" + e.properties[k].name + "' is not supported");
        }
        index[e.properties[k].name] = k;
      }
      for (const char* required : {"x", "y", "z"}) {
        if (!index.contains(required)) {
          throw RaytraceError(path + ": element vertex has no property '" + required + "'");
        }
      }
      has_normals = index.contains("nx") && index.contains("ny") && index.contains("nz");
      has_colors = index.contains("red") && index.contains("green") && index.contains("blue");
      std::string u_name, v_name;
      for (auto [u, v] :
           {std::pair{"s", "t"}, std::pair{"u", "v"}, std::pair{"texture_u", "texture_v"}}) {
        if (index.contains(u) && index.contains(v)) {
          u_name = u;
          v_name = v;
          has_uvs = true;
          break;
        }
      }
      std::vector<double> values(e.properties.size());
      for (size_t i = 0; i < e.count; ++i) {
        for (size_t k = 0; k < e.properties.size(); ++k) {
          values[k] = reader.Read(e.properties[k].type, "vertex");
        }
        auto get = [&](const std::string& name) { return static_cast<float>(values[index[name]]); };
        for (const char* axis : {"x", "y", "z"}) {
          if (!std::isfinite(get(axis))) {
            reader.Fail("vertex", "vertex " + std::to_string(i) + " has a non-finite " + axis);
          }
        }
        mesh.positions.push_back({get("x"), get("y"), get("z")});
        if (has_normals) mesh.normals.push_back(Normalize({get("nx"), get("ny"), get("nz")}));
        if (has_colors) {
          Vec3 c{};
          const char* names[3] = {"red", "green", "blue"};
          for (int k = 0; k < 3; ++k) {
            const PlyProperty& p = e.properties[index[names[k]]];
            const double raw = values[index[names[k]]];
            c[k] = (p.type == "float" || p.type == "float32" || p.type == "double" ||
                    p.type == "float64")
                       ? static_cast<float>(raw)
                       : Srgb8ToLinear(static_cast<uint8_t>(std::clamp(raw, 0.0, 255.0)));
          }
          mesh.colors.push_back(c);
        }
        if (has_uvs) mesh.uvs.push_back({get(u_name), get(v_name)});
      }
    } else if (e.name == "face") {
      has_face = true;
      std::vector<uint32_t> polygon;
      for (size_t i = 0; i < e.count; ++i) {
        for (const PlyProperty& p : e.properties) {
          if (p.count_type.empty()) {
            reader.Read(p.type, "face");
            continue;
          }
          const uint32_t count =
              reader.ReadIndex(p.count_type, "face", "face " + std::to_string(i) + " vertex count");
          if (count > 1000) {
            reader.Fail("face", "face " + std::to_string(i) + " has an invalid vertex count " +
                                    std::to_string(count));
          }
          polygon.clear();
          for (uint32_t k = 0; k < count; ++k) {
            const uint32_t idx =
                reader.ReadIndex(p.type, "face", "face " + std::to_string(i) + " vertex index");
            if (idx >= mesh.positions.size()) {
              reader.Fail("face", "face " + std::to_string(i) + " uses vertex " +
                                      std::to_string(idx) + " of " +
                                      std::to_string(mesh.positions.size()));
            }
            polygon.push_back(idx);
          }
          if (p.name != "vertex_indices" && p.name != "vertex_index") continue;
          if (polygon.size() < 3) {
            reader.Fail("face", "face " + std::to_string(i) + " has fewer than 3 vertices");
          }
          for (size_t k = 1; k + 1 < polygon.size(); ++k) {
            mesh.triangles.push_back({polygon[0], polygon[k], polygon[k + 1]});
          }
        }
      }
    } else {
      for (size_t i = 0; i < e.count; ++i) {
        for (const PlyProperty& p : e.properties) {
          if (p.count_type.empty()) {
            reader.Read(p.type, e.name);
          } else {
            const uint32_t count = reader.ReadIndex(p.count_type, e.name, "list count");
            for (uint32_t k = 0; k < count; ++k) reader.Read(p.type, e.name);
          }
        }
      }
    }
  }
  if (!has_vertex) throw RaytraceError(path + ": PLY file has no 'vertex' element");
  if (!has_face || mesh.triangles.empty()) {
    throw RaytraceError(path +
                        ": PLY file has no faces (expected element face with "
                        "property list ... vertex_indices)");
  }
  if (!has_normals) mesh.ComputeNormals();
  mesh.Validate(path);
  return mesh;
}

Mesh LoadMesh(const std::string& path) {
  const size_t dot = path.rfind('.');
  const std::string ext = dot == std::string::npos ? "" : Lower(path.substr(dot + 1));
  if (ext == "obj") return LoadObj(path);
  if (ext == "ply") return LoadPly(path);
  throw RaytraceError(path + ": unknown mesh format (expected a .obj or .ply file)");
}

}  // namespace probeless::raytrace
