// Shared by the fuzz targets whose readers take a path: one scratch file (or folder) per process,
// rewritten for every input.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

namespace probeless::fuzz {

// A contract check: libFuzzer reports the abort as a crash and keeps the input.
inline void Check(bool condition) {
  if (!condition) std::abort();
}

// /tmp/probeless_<tag>_fuzz.<pid>/ (created once); the readers' messages name files inside it.
inline const std::string& ScratchDir(const char* tag) {
  static const std::string dir = [&] {
    const std::string d =
        std::string("/tmp/probeless_") + tag + "_fuzz." + std::to_string(::getpid());
    std::filesystem::create_directories(d);
    return d;
  }();
  return dir;
}

// Writes `size` bytes to `path` (replacing it). False if it cannot (the input is then skipped).
inline bool WriteBytes(const std::string& path, const uint8_t* data, size_t size) {
  FILE* file = std::fopen(path.c_str(), "wb");
  if (!file) return false;
  const bool ok = std::fwrite(data, 1, size, file) == size;
  return std::fclose(file) == 0 && ok;
}

}  // namespace probeless::fuzz
