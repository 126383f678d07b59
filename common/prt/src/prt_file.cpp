// The PRT file format (docs/render.md): little-endian, 40-byte header
//   char magic[8] = "PBLPRT01"; u32 bands; u32 vertex_count; u32 triangle_count; u32 flags
//   (bit 0: colours present); u32 reserved[4] = 0
// then f32 positions[V][3], f32 normals[V][3], (f32 colours[V][3] if flag 0), u32 triangles[T][3],
// f32 transfer[V][bands^2].
#include <bit>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "probeless/prt/prt.h"

namespace probeless::prt {

namespace {

static_assert(std::endian::native == std::endian::little, "PRT files are little-endian");

constexpr char kMagic[8] = {'P', 'B', 'L', 'P', 'R', 'T', '0', '1'};

struct Header {
  char magic[8];
  uint32_t bands;
  uint32_t vertex_count;
  uint32_t triangle_count;
  uint32_t flags;
  uint32_t reserved[4];
};
static_assert(sizeof(Header) == 40);

template <class T>
void Write(std::ofstream& out, const std::vector<T>& v) {
  out.write(reinterpret_cast<const char*>(v.data()),
            static_cast<std::streamsize>(v.size() * sizeof(T)));
}

template <class T>
void Read(std::ifstream& in, std::vector<T>& v, size_t n, const std::string& path,
          const char* what) {
  v.resize(n);
  in.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(n * sizeof(T)));
  if (!in) throw PrtError(path + ": truncated " + what);
}

}  // namespace

void SavePrt(const TransferMesh& mesh, const std::string& path) {
  mesh.Validate(path);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw PrtError(path + ": cannot open for writing");
  Header h{};
  std::memcpy(h.magic, kMagic, sizeof(kMagic));
  h.bands = static_cast<uint32_t>(mesh.bands);
  h.vertex_count = static_cast<uint32_t>(mesh.mesh.positions.size());
  h.triangle_count = static_cast<uint32_t>(mesh.mesh.triangles.size());
  const bool colours = mesh.mesh.colors.size() == mesh.mesh.positions.size();
  h.flags = colours ? 1u : 0u;
  out.write(reinterpret_cast<const char*>(&h), sizeof(h));
  Write(out, mesh.mesh.positions);
  Write(out, mesh.mesh.normals);
  if (colours) Write(out, mesh.mesh.colors);
  Write(out, mesh.mesh.triangles);
  Write(out, mesh.transfer);
  if (!out) throw PrtError(path + ": write failed");
}

TransferMesh LoadPrt(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw PrtError(path + ": cannot open");
  Header h{};
  in.read(reinterpret_cast<char*>(&h), sizeof(h));
  if (!in || std::memcmp(h.magic, kMagic, sizeof(kMagic)) != 0) {
    throw PrtError(path + ": not a PRT file (expected magic PBLPRT01)");
  }
  if (h.bands < 1 || h.bands > 5) {
    throw PrtError(path + ": bands " + std::to_string(h.bands) + " out of range 1..5");
  }
  if (h.vertex_count == 0 || h.triangle_count == 0 || h.vertex_count > (1u << 28) ||
      h.triangle_count > (1u << 28) || (h.flags & ~1u) != 0) {
    throw PrtError(path + ": malformed header (vertex_count " + std::to_string(h.vertex_count) +
                   ", triangle_count " + std::to_string(h.triangle_count) + ", flags " +
                   std::to_string(h.flags) + ")");
  }
  // The header's counts are checked against the file's size before anything is allocated: a
  // short file must not ask for gigabytes.
  {
    std::error_code error;
    const uintmax_t file_bytes = std::filesystem::file_size(path, error);
    if (error) throw PrtError(path + ": cannot read its size (" + error.message() + ")");
    const uint64_t v = h.vertex_count;
    const uint64_t sections[5] = {12 * v, 12 * v, (h.flags & 1u) ? 12 * v : 0,
                                  12 * static_cast<uint64_t>(h.triangle_count),
                                  4 * v * h.bands * h.bands};
    const char* names[5] = {"positions", "normals", "colours", "triangles", "transfer"};
    uint64_t end = sizeof(h);
    for (int k = 0; k < 5; ++k) {
      end += sections[k];
      if (end > file_bytes) throw PrtError(path + ": truncated " + names[k]);
    }
    if (end < file_bytes) throw PrtError(path + ": trailing bytes");
  }
  TransferMesh m;
  m.bands = static_cast<int>(h.bands);
  Read(in, m.mesh.positions, h.vertex_count, path, "positions");
  Read(in, m.mesh.normals, h.vertex_count, path, "normals");
  if (h.flags & 1u) Read(in, m.mesh.colors, h.vertex_count, path, "colours");
  Read(in, m.mesh.triangles, h.triangle_count, path, "triangles");
  Read(in, m.transfer, static_cast<size_t>(h.vertex_count) * h.bands * h.bands, path, "transfer");
  if (in.peek() != std::char_traits<char>::eof()) throw PrtError(path + ": trailing bytes");
  m.Validate(path);
  return m;
}

}  // namespace probeless::prt
