// libFuzzer target: a received bus sample of arbitrary bytes read as a message the way the nodes
// read it (msgs_reader_check.h). The first byte picks the message type; the rest is the sample.
// Only msgs::MessageError may escape, with a one-line message.
#include <cstring>

#include "fuzz_file.h"
#include "msgs_reader_check.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1 || size > (1u << 20)) return 0;
  const probeless::fuzz::AlignedSample sample(data + 1, size - 1);
  try {
    probeless::fuzz::ReadAsMessage(data[0], sample.bytes());
  } catch (const probeless::msgs::MessageError& e) {
    probeless::fuzz::Check(std::strchr(e.what(), '\n') == nullptr);
  }
  return 0;
}
