// Recovery of truncated MCAP files (every prefix of a file; a writer killed with SIGKILL) and
// rejection of corrupt ones (every byte flipped): the reader recovers exactly the messages of the
// complete chunks, or throws a one-line LogError naming the file, and never crashes.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "log_test_util.h"
#include "probeless/log/mcap_reader.h"
#include "probeless/log/mcap_writer.h"

namespace probeless::log {
namespace {

using testing::InLogTimeOrder;
using testing::ListRecords;
using testing::RandomBytes;
using testing::ReadAll;
using testing::ReadFileBytes;
using testing::TempDir;
using testing::Written;

// A small file with many chunks, and for every message the chunk it landed in.
struct ChunkedFile {
  std::vector<std::byte> bytes;
  std::vector<Written> written;
  std::vector<size_t> chunk_of;        // per written message
  std::vector<uint64_t> chunk_ends;    // end offset of each Chunk record
  std::vector<uint64_t> channel_ends;  // end offset of each Channel record
};

ChunkedFile WriteChunked(const std::string& path, Compression compression, int messages,
                         uint64_t chunk_size) {
  ChunkedFile file;
  std::mt19937_64 rng(1234);
  WriterOptions options;
  options.compression = compression;
  options.chunk_size = chunk_size;
  {
    McapWriter writer(path, options);
    const uint16_t schema = writer.AddSchema("test/msg/Blob", "ros2msg", "uint8[] data\n");
    const uint16_t a = writer.AddChannel("/a", "cdr", schema);
    const uint16_t b = writer.AddChannel("/b", "cdr", schema, {{"k", "v"}});
    size_t pending_from = 0;
    for (int i = 0; i < messages; ++i) {
      const uint64_t time = 100 + static_cast<uint64_t>(i) * 10 - (i % 4 == 3 ? 25 : 0);
      Written w{i % 3 == 0 ? "/b" : "/a", static_cast<uint32_t>(i), time, time + 1,
                RandomBytes(rng, rng() % (chunk_size / 2))};
      const uint64_t chunks_before = writer.stats().chunks;
      writer.Write(w.topic == "/a" ? a : b, w.sequence, w.log_time, w.publish_time, w.data);
      file.written.push_back(std::move(w));
      file.chunk_of.push_back(0);
      if (writer.stats().chunks != chunks_before) {  // the open chunk was written
        for (size_t j = pending_from; j < file.written.size(); ++j) {
          file.chunk_of[j] = chunks_before;
        }
        pending_from = file.written.size();
      }
    }
    const uint64_t last_chunk = writer.stats().chunks;
    for (size_t j = pending_from; j < file.written.size(); ++j) file.chunk_of[j] = last_chunk;
    writer.Close();
  }
  file.bytes = ReadFileBytes(path);
  for (const auto& record : ListRecords(file.bytes)) {
    if (record.opcode == 0x06) file.chunk_ends.push_back(record.end());
    if (record.opcode == 0x04 && file.chunk_ends.empty()) file.channel_ends.push_back(record.end());
  }
  return file;
}

class TruncationTest : public ::testing::TestWithParam<Compression> {};

TEST_P(TruncationTest, EveryPrefixRecoversTheCompleteChunksOrFailsCleanly) {
  TempDir dir;
  const ChunkedFile file = WriteChunked(dir.File("full.mcap"), GetParam(), 60, 400);
  ASSERT_GT(file.chunk_ends.size(), 10u);
  ASSERT_EQ(file.chunk_of.back() + 1, file.chunk_ends.size());

  for (size_t cut = 0; cut <= file.bytes.size(); ++cut) {
    SCOPED_TRACE("prefix of " + std::to_string(cut) + " bytes of " +
                 std::to_string(file.bytes.size()));
    const std::string name = "prefix";
    const std::span<const std::byte> prefix(file.bytes.data(), cut);
    if (cut < 8) {
      try {
        McapReader::FromBuffer(name, prefix);
        FAIL() << "no error";
      } catch (const LogError& error) {
        EXPECT_EQ(std::string(error.what()), "prefix: offset 0: file of " + std::to_string(cut) +
                                                 " bytes is too short for the MCAP magic");
      }
      continue;
    }
    std::vector<Written> expected;
    uint64_t expected_bytes = 0;
    for (size_t i = 0; i < file.written.size(); ++i) {
      if (file.chunk_ends[file.chunk_of[i]] <= cut) {
        expected.push_back(file.written[i]);
        expected_bytes += file.written[i].data.size();
      }
    }
    McapReader reader = McapReader::FromBuffer(name, prefix);
    const RecoveryReport& report = reader.recovery();
    const bool complete = cut == file.bytes.size();
    ASSERT_EQ(report.truncated, !complete);
    ASSERT_EQ(report.messages, expected.size());
    ASSERT_EQ(ReadAll(reader), InLogTimeOrder(expected));
    if (!complete) {
      EXPECT_FALSE(report.indexed);
      EXPECT_EQ(report.message_bytes, expected_bytes);
      EXPECT_LE(report.valid_bytes, cut);
      EXPECT_FALSE(report.detail.empty());
      EXPECT_EQ(report.detail.find('\n'), std::string::npos);
      size_t complete_chunks = 0;
      for (uint64_t end : file.chunk_ends) complete_chunks += end <= cut ? 1 : 0;
      EXPECT_EQ(report.chunks, complete_chunks);
      if (complete_chunks > 0) {
        EXPECT_GE(report.valid_bytes, file.chunk_ends[complete_chunks - 1]);
      }
      EXPECT_EQ(reader.statistics().message_count, expected.size());
      size_t channels = 0;
      for (uint64_t end : file.channel_ends) channels += end <= cut ? 1 : 0;
      EXPECT_EQ(reader.channels().size(), channels);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Compressions, TruncationTest,
                         ::testing::Values(Compression::kNone, Compression::kZstd,
                                           Compression::kLz4),
                         [](const auto& info) {
                           return std::string(CompressionOptionName(info.param));
                         });

TEST(TruncationTest, LargerFileCutAtStridedOffsets) {
  TempDir dir;
  const ChunkedFile file = WriteChunked(dir.File("big.mcap"), Compression::kZstd, 400, 8192);
  size_t previous = 0;
  for (size_t cut = 8; cut < file.bytes.size(); cut += 211) {
    McapReader reader =
        McapReader::FromBuffer("big", std::span<const std::byte>(file.bytes.data(), cut));
    ASSERT_TRUE(reader.truncated());
    size_t expected = 0;
    for (size_t i = 0; i < file.written.size(); ++i) {
      expected += file.chunk_ends[file.chunk_of[i]] <= cut ? 1 : 0;
    }
    ASSERT_EQ(ReadAll(reader).size(), expected) << "cut at " << cut;
    ASSERT_GE(expected, previous);  // longer prefixes never recover less
    previous = expected;
  }
  EXPECT_GT(previous, 300u);
}

TEST(TruncationTest, WriterKilledWithSigkillLeavesARecoverableFile) {
  TempDir dir;
  const std::string path = dir.File("killed.mcap");
  int ready[2];
  ASSERT_EQ(pipe(ready), 0);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    close(ready[0]);
    WriterOptions options;
    options.compression = Compression::kLz4;
    options.chunk_size = 64 * 1024;
    McapWriter writer(path, options);
    const uint16_t channel = writer.AddChannel("/frames", "raw", 0);
    std::vector<std::byte> payload(10'000);
    for (uint32_t i = 0; i < 100; ++i) {
      std::memcpy(payload.data(), &i, sizeof(i));
      writer.Write(channel, i, 1000 + i, 1000 + i, payload);
    }
    writer.Flush();  // everything so far is in the file
    for (uint32_t i = 100; i < 105; ++i) writer.Write(channel, i, 1000 + i, 1000 + i, payload);
    const char byte = 'k';
    (void)!write(ready[1], &byte, 1);
    pause();  // killed here, with 5 messages in the open chunk
    _exit(0);
  }
  close(ready[1]);
  char byte = 0;
  ASSERT_EQ(read(ready[0], &byte, 1), 1);
  close(ready[0]);
  ASSERT_EQ(kill(child, SIGKILL), 0);
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(status));

  McapReader reader(path);
  EXPECT_TRUE(reader.truncated());
  EXPECT_EQ(reader.recovery().messages, 100u);
  EXPECT_EQ(reader.recovery().message_bytes, 100u * 10'000);
  const auto messages = ReadAll(reader);
  ASSERT_EQ(messages.size(), 100u);
  for (uint32_t i = 0; i < 100; ++i) {
    uint32_t stored = 0;
    std::memcpy(&stored, messages[i].data.data(), sizeof(stored));
    EXPECT_EQ(stored, i);
    EXPECT_EQ(messages[i].log_time, 1000u + i);
  }
  EXPECT_EQ(reader.recovery().detail, "file ends after a complete record at offset " +
                                          std::to_string(reader.recovery().valid_bytes));
}

// Every byte of a complete file flipped: a clean one-line LogError naming the input, or (for bytes
// no check covers, such as a profile string or an index the reader does not need) exactly the
// original messages.
class CorruptionTest : public ::testing::TestWithParam<Compression> {};

TEST_P(CorruptionTest, EveryFlippedByteIsRejectedCleanlyOrHarmless) {
  TempDir dir;
  const ChunkedFile file = WriteChunked(dir.File("flip.mcap"), GetParam(), 24, 300);
  const std::vector<Written> original = InLogTimeOrder(file.written);
  size_t errors = 0;
  size_t harmless = 0;
  for (bool force_scan : {false, true}) {
    ReaderOptions options;
    options.force_scan = force_scan;
    for (size_t at = 0; at < file.bytes.size(); ++at) {
      for (std::byte mask : {std::byte{0x01}, std::byte{0x80}, std::byte{0xFF}}) {
        std::vector<std::byte> bytes = file.bytes;
        bytes[at] ^= mask;
        try {
          McapReader reader = McapReader::FromBuffer("flipped", bytes, options);
          ASSERT_EQ(ReadAll(reader), original)
              << "byte " << at << " flipped with " << static_cast<int>(mask)
              << (force_scan ? " (scan)" : " (indexed)");
          ++harmless;
        } catch (const LogError& error) {
          const std::string what = error.what();
          ASSERT_EQ(what.rfind("flipped: ", 0), 0u) << what;
          ASSERT_EQ(what.find('\n'), std::string::npos) << what;
          ++errors;
        }
      }
    }
  }
  // Most bytes are covered by a check (CRCs, lengths, index consistency).
  EXPECT_GT(errors, 2 * harmless);
}

INSTANTIATE_TEST_SUITE_P(Compressions, CorruptionTest,
                         ::testing::Values(Compression::kNone, Compression::kZstd,
                                           Compression::kLz4),
                         [](const auto& info) {
                           return std::string(CompressionOptionName(info.param));
                         });

}  // namespace
}  // namespace probeless::log
