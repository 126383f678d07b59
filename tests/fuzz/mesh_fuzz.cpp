// libFuzzer target: raytrace::LoadObj and LoadPly (ASCII and binary) on arbitrary bytes; the
// first byte picks the reader. Only RaytraceError may escape; an accepted mesh must be valid
// (Mesh::Validate), finite and have triangles.
#include <cmath>

#include "fuzz_file.h"
#include "probeless/raytrace/mesh.h"

namespace {

using probeless::fuzz::Check;
constexpr size_t kMaxInputBytes = 64 * 1024;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1 || size > kMaxInputBytes) return 0;
  const bool ply = data[0] % 2 == 1;
  const std::string path = probeless::fuzz::ScratchDir("mesh") + (ply ? "/mesh.ply" : "/mesh.obj");
  if (!probeless::fuzz::WriteBytes(path, data + 1, size - 1)) return 0;
  try {
    const probeless::raytrace::Mesh mesh =
        ply ? probeless::raytrace::LoadPly(path) : probeless::raytrace::LoadObj(path);
    mesh.Validate("fuzz");
    Check(!mesh.triangles.empty());
    for (const auto& p : mesh.positions) {
      Check(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z));
    }
  } catch (const probeless::raytrace::RaytraceError&) {
    // Rejected with a message: the contract.
  }
  return 0;
}
