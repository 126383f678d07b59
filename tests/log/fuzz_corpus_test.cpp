// Replays the fuzzers' seed corpora (tests/fuzz/corpus/mcap_reader, .../cdr_decoder) through the
// fuzz entry points in every build, without libFuzzer: the entry points abort on any broken
// invariant, and the seeds must include readable inputs so the targets start from real files.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "probeless/log/cdr.h"
#include "probeless/log/mcap_reader.h"
#include "probeless/log/ros2.h"

namespace probeless::log::fuzz {
int FuzzMcapReader(const uint8_t* data, size_t size);
int FuzzCdrDecoder(const uint8_t* data, size_t size);
}  // namespace probeless::log::fuzz

namespace probeless::log {
namespace {

std::vector<std::vector<uint8_t>> Corpus(const std::string& name) {
  std::vector<std::vector<uint8_t>> files;
  const std::filesystem::path dir =
      std::filesystem::path(PROBELESS_SOURCE_DIR) / "tests/fuzz/corpus" / name;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    std::ifstream in(entry.path(), std::ios::binary);
    files.emplace_back((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }
  return files;
}

TEST(FuzzCorpusTest, McapReaderSeeds) {
  const auto corpus = Corpus("mcap_reader");
  ASSERT_GE(corpus.size(), 8u);
  int readable = 0;
  int truncated = 0;
  int with_messages = 0;
  for (const auto& seed : corpus) {
    fuzz::FuzzMcapReader(seed.data(), seed.size());
    try {
      McapReader reader = McapReader::FromBuffer(
          "seed", std::span(reinterpret_cast<const std::byte*>(seed.data()), seed.size()));
      ++readable;
      truncated += reader.truncated() ? 1 : 0;
      with_messages += reader.recovery().messages > 0 ? 1 : 0;
    } catch (const LogError&) {
    }
  }
  EXPECT_GE(readable, 6);
  EXPECT_GE(truncated, 2);
  EXPECT_GE(with_messages, 5);
}

TEST(FuzzCorpusTest, CdrDecoderSeeds) {
  const auto corpus = Corpus("cdr_decoder");
  ASSERT_GE(corpus.size(), AllRos2Converters().size());
  size_t decodable = 0;
  for (const auto& seed : corpus) {
    fuzz::FuzzCdrDecoder(seed.data(), seed.size());
    ASSERT_FALSE(seed.empty());
    const Ros2Converter& converter = *AllRos2Converters()[seed[0] % AllRos2Converters().size()];
    try {
      DecodeRos2(converter,
                 std::span(reinterpret_cast<const std::byte*>(seed.data() + 1), seed.size() - 1));
      ++decodable;
    } catch (const CdrError&) {
    }
  }
  EXPECT_GE(decodable, AllRos2Converters().size());  // a valid seed for every type
}

}  // namespace
}  // namespace probeless::log
