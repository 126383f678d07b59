// libFuzzer target: the CDR decoders of every ROS 2 conversion (probeless::log::Ros2Converter) on
// arbitrary bytes. Byte 0 picks the converter; the rest is the CDR message. Each input must throw
// CdrError or decode to a valid probeless message whose size is bounded by the input, which
// re-encodes and decodes to the same bytes. Seeds: tests/fuzz/corpus/cdr_decoder.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <map>
#include <span>
#include <string>
#include <vector>

#include "probeless/log/cdr.h"
#include "probeless/log/ros2.h"

namespace probeless::log::fuzz {

int FuzzCdrDecoder(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const auto converters = AllRos2Converters();
  const Ros2Converter& converter = *converters[data[0] % converters.size()];
  const std::span<const std::byte> cdr(reinterpret_cast<const std::byte*>(data + 1), size - 1);
  const std::map<std::string, std::string> metadata = {{"probeless.child_frame_id", "child"},
                                                       {"probeless.depth_scale", "0.001"}};
  try {
    const size_t decoded_size = converter.DecodedSize(cdr);
    // Bounded by the input: the largest fixed struct plus plane alignment padding.
    if (decoded_size > cdr.size() + 16384) std::abort();
    MessageBuffer decoded(decoded_size);
    if (converter.Decode(cdr, metadata, decoded.bytes()) != decoded_size) std::abort();
    // A decoded message is valid: it encodes, and decodes again to the same bytes.
    const std::vector<std::byte> again = EncodeRos2(converter, decoded.bytes());
    const MessageBuffer round_trip = DecodeRos2(converter, again, metadata);
    if (round_trip.size() != decoded.size() ||
        std::memcmp(round_trip.bytes().data(), decoded.bytes().data(), decoded.size()) != 0) {
      std::abort();
    }
  } catch (const CdrError&) {
    // Clean rejection of malformed CDR.
  }
  // The generic reader on the same bytes.
  try {
    CdrReader reader(cdr, "fuzz");
    reader.String("s");
    reader.Sequence<double>("d");
    reader.Bool("b");
    reader.SequenceBytes<uint16_t>("u");
  } catch (const CdrError&) {
  }
  return 0;
}

}  // namespace probeless::log::fuzz

#ifndef PROBELESS_FUZZ_NO_MAIN
extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return probeless::log::fuzz::FuzzCdrDecoder(data, size);
}
#endif
