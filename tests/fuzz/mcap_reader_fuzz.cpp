// libFuzzer target: McapReader on arbitrary bytes (complete, truncated and corrupt files). Every
// input must either read (messages iterate, indexed and scanned) or throw LogError; never crash,
// hang or allocate without bound. Seeds: tests/fuzz/corpus/mcap_reader (built by
// tests/log/CMakeLists.txt with -DPROBELESS_BUILD_FUZZERS=ON; also replayed by
// log_fuzz_corpus_test in every build).
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>

#include "probeless/log/mcap_reader.h"

namespace probeless::log::fuzz {

int FuzzMcapReader(const uint8_t* data, size_t size) {
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data), size);
  for (bool force_scan : {false, true}) {
    ReaderOptions options;
    options.max_chunk_bytes = 16 << 20;  // keep the fuzzer within its memory limit
    options.force_scan = force_scan;
    try {
      McapReader reader = McapReader::FromBuffer("fuzz-input", bytes, options);
      uint64_t count = 0;
      MessageCursor cursor = reader.Messages();
      MessageView message;
      uint64_t previous_time = 0;
      while (cursor.Next(message)) {
        if (message.channel == nullptr || message.log_time_ns < previous_time) std::abort();
        if (message.channel->schema_id != 0 && message.schema == nullptr) std::abort();
        previous_time = message.log_time_ns;
        ++count;
      }
      // A scan counts exactly the messages the cursor later returns.
      if (!reader.recovery().indexed && count != reader.recovery().messages) std::abort();
      ReadOptions filtered;
      filtered.topics = {"/a"};
      filtered.start_time_ns = 2;
      filtered.end_time_ns = 1'000'000;
      MessageCursor some = reader.Messages(filtered);
      while (some.Next(message)) {
        if (message.channel->topic != "/a" || message.log_time_ns < 2 ||
            message.log_time_ns >= 1'000'000) {
          std::abort();
        }
      }
    } catch (const LogError&) {
      // Clean rejection of a corrupt input.
    }
  }
  return 0;
}

}  // namespace probeless::log::fuzz

#ifndef PROBELESS_FUZZ_NO_MAIN
extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return probeless::log::fuzz::FuzzMcapReader(data, size);
}
#endif
