// libFuzzer target: the dataset sources' text files on arbitrary bytes. First byte even: a TUM
// RGB-D folder whose rgb.txt, depth.txt and groundtruth.txt are the rest of the input split at
// NUL bytes (the image files they name do not exist); odd: a 7-Scenes pose file (16 numbers, a
// rigid 4x4 matrix). Only DatasetError may escape; an accepted pose must be a unit quaternion.
#include <cmath>
#include <fstream>
#include <string_view>

#include "fuzz_file.h"
#include "internal.h"
#include "probeless/dataset/datasets.h"
#include "text_io.h"

namespace {

using probeless::fuzz::Check;
namespace ds = probeless::dataset;
constexpr size_t kMaxInputBytes = 64 * 1024;

void WriteText(const std::string& path, std::string_view text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
}

void FuzzTum(std::string_view input) {
  const std::string dir = probeless::fuzz::ScratchDir("dataset_text") + "/tum";
  std::filesystem::create_directories(dir);
  const char* names[3] = {"rgb.txt", "depth.txt", "groundtruth.txt"};
  for (int i = 0; i < 3; ++i) {
    const size_t nul = input.find('\0');
    const std::string path = dir + "/" + names[i];
    if (i == 2 && input.empty()) {
      std::filesystem::remove(path);  // ground truth is optional
      break;
    }
    WriteText(path, input.substr(0, nul));
    input = nul == std::string_view::npos ? std::string_view() : input.substr(nul + 1);
  }
  ds::DatasetOptions options;
  auto source = ds::internal::OpenTum(dir, options);
  while (source->Next()) {
  }
}

void FuzzPose(std::string_view input) {
  const std::string path = probeless::fuzz::ScratchDir("dataset_text") + "/frame-000000.pose.txt";
  WriteText(path, input);
  const std::vector<double> m =
      ds::internal::ReadNumberFile(path, 16, "7-Scenes pose", "16 numbers (a 4x4 matrix)");
  const auto t = ds::internal::TransformFromMatrix(m, path);
  const auto& q = t.rotation;
  Check(std::abs(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z - 1) < 1e-6);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1 || size > kMaxInputBytes) return 0;
  const std::string_view input(reinterpret_cast<const char*>(data + 1), size - 1);
  try {
    if (data[0] % 2 == 0) {
      FuzzTum(input);
    } else {
      FuzzPose(input);
    }
  } catch (const ds::DatasetError&) {
    // Rejected with a message: the contract.
  }
  return 0;
}
