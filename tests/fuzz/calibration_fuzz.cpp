// libFuzzer target: calib::ReadCalibrationFile (ROS camera_info YAML and OpenCV FileStorage YAML /
// XML, chosen by content) on arbitrary bytes. The first byte picks a prefix that steers the input
// into one of the three parsers; the rest is the file. Only CalibrationError may escape, and an
// accepted file must meet Intrinsics' contract.
#include <cmath>
#include <cstring>

#include "fuzz_file.h"
#include "probeless/calib/calibration.h"

namespace {

using probeless::fuzz::Check;
constexpr size_t kMaxInputBytes = 16 * 1024;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1 || size > kMaxInputBytes) return 0;
  static const char* const kPrefixes[] = {"", "%YAML:1.0\n", "<?xml version=\"1.0\"?>\n"};
  const std::string prefix = kPrefixes[data[0] % 3];
  std::string bytes = prefix;
  bytes.append(reinterpret_cast<const char*>(data + 1), size - 1);
  const std::string path = probeless::fuzz::ScratchDir("calibration") + "/camera_info.yaml";
  if (!probeless::fuzz::WriteBytes(path, reinterpret_cast<const uint8_t*>(bytes.data()),
                                   bytes.size())) {
    return 0;
  }
  try {
    const probeless::calib::Intrinsics k = probeless::calib::ReadCalibrationFile(path);
    for (double v : {k.fx, k.fy, k.cx, k.cy}) Check(std::isfinite(v));
    Check(k.fx > 0 && k.fy > 0);
    Check(k.distortion.size() == probeless::msgs::DistortionCoefficientCount(k.model));
    for (double d : k.distortion) Check(std::isfinite(d));
  } catch (const probeless::calib::CalibrationError& e) {
    Check(std::strchr(e.what(), '\n') == nullptr || std::strstr(e.what(), "YAML") != nullptr);
  }
  return 0;
}
