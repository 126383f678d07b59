// libFuzzer target: prt::LoadPrt (the binary PRT transfer-mesh file, docs/render.md) on arbitrary
// bytes. Only PrtError may escape, no allocation may exceed what the file's size allows (ASan's
// allocation limit catches a header asking for gigabytes), and an accepted mesh must validate.
#include <cmath>

#include "fuzz_file.h"
#include "probeless/prt/prt.h"

namespace {

using probeless::fuzz::Check;
constexpr size_t kMaxInputBytes = 256 * 1024;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > kMaxInputBytes) return 0;
  const std::string path = probeless::fuzz::ScratchDir("prt") + "/mesh.prt";
  if (!probeless::fuzz::WriteBytes(path, data, size)) return 0;
  try {
    const probeless::prt::TransferMesh mesh = probeless::prt::LoadPrt(path);
    mesh.Validate("fuzz");
    Check(mesh.transfer.size() ==
          mesh.mesh.positions.size() * static_cast<size_t>(mesh.coefficient_count()));
  } catch (const probeless::prt::PrtError&) {
    // Rejected with a message: the contract.
  }
  return 0;
}
