// libFuzzer target: face_light::ParseModel (the version-2 face light model file) on arbitrary
// text. Only FaceLightError may escape; an accepted model must validate and survive a round trip
// through SerializeModel unchanged.
#include "fuzz_file.h"
#include "probeless/face_light/model.h"

namespace {

using probeless::fuzz::Check;
namespace fl = probeless::face_light;
constexpr size_t kMaxInputBytes = 256 * 1024;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > kMaxInputBytes) return 0;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const fl::FaceLightModel model = fl::ParseModel(text, "fuzz/model.txt");
    model.Validate();
    const std::string serialized = fl::SerializeModel(model);
    Check(fl::SerializeModel(fl::ParseModel(serialized, "fuzz/round_trip")) == serialized);
  } catch (const fl::FaceLightError&) {
    // Rejected with a message: the contract.
  }
  return 0;
}
