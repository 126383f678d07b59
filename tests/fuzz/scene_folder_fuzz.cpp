// libFuzzer target: the composite evaluation's scene-folder readers (insertion.yaml, truth.json,
// rgb.txt; probeless/eval/scene_folder.h) on arbitrary bytes. The first byte picks the reader, the
// rest is the file. The only exception a reader may throw is EvalError; anything else escapes and
// libFuzzer reports it as a crash. What a reader accepts is checked against its contract.
#include <unistd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "probeless/eval/scene_folder.h"

namespace {

using probeless::eval::EvalError;

constexpr size_t kMaxInputBytes = 64 * 1024;

void Check(bool condition) {
  if (!condition) std::abort();
}

// One file per process, written for every input (the readers take a path) and removed after it.
const std::string& InputPath() {
  static const std::string path = "/tmp/probeless_scene_folder_fuzz." + std::to_string(::getpid());
  return path;
}

void CheckInsertion(const std::string& path) {
  for (const auto& o : probeless::eval::LoadInsertion(path, "fuzz/insertion.yaml")) {
    if (o.shape == probeless::eval::Shape::kSphere) Check(o.radius > 0 && std::isfinite(o.radius));
    if (o.shape == probeless::eval::Shape::kBox) {
      for (double s : o.size) Check(s > 0 && std::isfinite(s));
    }
    for (double a : o.albedo) Check(a >= 0 && a <= 1);
    for (double p : o.position) Check(std::isfinite(p));
    double n = 0;
    for (double q : o.rotation) n += q * q;
    Check(std::abs(n - 1) < 1e-6);
    Check(std::isfinite(o.BoundingRadius()) && o.BoundingRadius() > 0);
  }
}

void CheckTruth(const std::string& path) {
  const probeless::eval::Truth truth = probeless::eval::LoadTruth(path, "fuzz/truth.json");
  for (const auto& f : truth.frames) {
    Check(std::isfinite(f.direct_to_ambient));
    if (const auto stamp = probeless::eval::ParseStampNs(f.timestamp)) truth.Find(*stamp);
  }
}

void CheckRgbList(const std::string& path) {
  const auto entries = probeless::eval::LoadRgbList(path, "fuzz/rgb.txt");
  for (size_t i = 1; i < entries.size(); ++i) {
    Check(entries[i - 1].stamp_ns <= entries[i].stamp_ns);
  }
  for (const auto& e : entries) Check(!e.file.empty());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1 || size > kMaxInputBytes) return 0;
  const std::string& path = InputPath();
  FILE* file = std::fopen(path.c_str(), "wb");
  if (!file) return 0;
  std::fwrite(data + 1, 1, size - 1, file);
  std::fclose(file);
  try {
    switch (data[0] % 3) {
      case 0:
        CheckInsertion(path);
        break;
      case 1:
        CheckTruth(path);
        break;
      default:
        CheckRgbList(path);
        break;
    }
  } catch (const EvalError&) {
    // Rejected with a message: the contract.
  }
  std::remove(path.c_str());
  return 0;
}
