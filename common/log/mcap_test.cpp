// McapWriter / McapReader: round trips, options, filters, ordering and error messages.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <map>
#include <random>
#include <string>
#include <vector>

#include "byte_io.h"
#include "crc32.h"
#include "log_test_util.h"
#include "mcap_format.h"
#include "probeless/log/mcap_reader.h"
#include "probeless/log/mcap_writer.h"
#include "probeless/testing/expect.h"
#include "records.h"

namespace probeless::log {
namespace {

using ::testing::HasSubstr;
using testing::InLogTimeOrder;
using testing::ListRecords;
using ::testing::MatchesRegex;
using testing::RandomBytes;
using testing::ReadAll;
using testing::ReadFileBytes;
using testing::RecordsWithOpcode;
using testing::TempDir;
using testing::WriteFileBytes;
using testing::Written;

std::span<const std::byte> Bytes(const std::string& text) {
  return {reinterpret_cast<const std::byte*>(text.data()), text.size()};
}

// Writes a file with many channels, random payloads, out-of-order times and messages larger than
// the chunk size; returns what was written (in write order).
std::vector<Written> WriteSample(const std::string& path, const WriterOptions& options,
                                 int messages = 600, uint64_t seed = 7) {
  std::mt19937_64 rng(seed);
  McapWriter writer(path, options);
  const uint16_t schema_a = writer.AddSchema("pkg/msg/A", "ros2msg", "int32 a\n");
  const uint16_t schema_b = writer.AddSchema("pkg/msg/B", "jsonschema", "{}");
  EXPECT_EQ(writer.AddSchema("pkg/msg/A", "ros2msg", "int32 a\n"), schema_a);  // deduplicated
  std::vector<uint16_t> channels;
  std::vector<std::string> topics;
  for (int c = 0; c < 20; ++c) {
    topics.push_back("/topic_" + std::to_string(c));
    channels.push_back(writer.AddChannel(topics.back(), c % 3 == 0 ? "json" : "cdr",
                                         c % 2 == 0 ? schema_a : (c == 5 ? 0 : schema_b),
                                         {{"index", std::to_string(c)}}));
  }
  writer.AddMetadata("recording", {{"robot", "probe-1"}, {"site", "lab"}});
  std::vector<Written> written;
  for (int i = 0; i < messages; ++i) {
    const size_t c = rng() % channels.size();
    size_t size = rng() % 3000;
    if (i % 150 == 7) size = options.chunk_size * 3 + 17;  // bigger than a chunk
    if (i % 97 == 3) size = 0;                             // empty payload
    // Mostly increasing times with jitter, some exact duplicates and some going backwards.
    uint64_t log_time = 1'000'000'000 + static_cast<uint64_t>(i) * 1000;
    if (i % 11 == 0) log_time -= 5'000;
    if (i % 13 == 0 && !written.empty()) log_time = written.back().log_time;
    Written w{topics[c], static_cast<uint32_t>(i + 1), log_time, log_time + 7,
              RandomBytes(rng, size)};
    writer.Write(channels[c], w.sequence, w.log_time, w.publish_time, w.data);
    written.push_back(std::move(w));
  }
  writer.Close();
  return written;
}

class RoundTripTest : public ::testing::TestWithParam<Compression> {};

TEST_P(RoundTripTest, ManyChannelsAndLargeMessagesComeBackByteExact) {
  TempDir dir;
  const std::string path = dir.File("sample.mcap");
  WriterOptions options;
  options.compression = GetParam();
  options.chunk_size = 16 * 1024;
  const std::vector<Written> written = WriteSample(path, options);

  McapReader reader(path);
  EXPECT_FALSE(reader.truncated());
  EXPECT_TRUE(reader.recovery().indexed);
  EXPECT_EQ(reader.profile(), "ros2");
  EXPECT_EQ(reader.library(), "probeless-log 0.1");
  ASSERT_EQ(reader.schemas().size(), 2u);
  EXPECT_EQ(reader.schemas().at(1).name, "pkg/msg/A");
  EXPECT_EQ(reader.schemas().at(2).encoding, "jsonschema");
  ASSERT_EQ(reader.channels().size(), 20u);
  EXPECT_EQ(reader.channels().at(6).topic, "/topic_5");
  EXPECT_EQ(reader.channels().at(6).schema_id, 0);
  EXPECT_EQ(reader.channels().at(4).message_encoding, "json");
  EXPECT_EQ(reader.channels().at(4).metadata.at("index"), "3");
  ASSERT_EQ(reader.metadata().size(), 1u);
  EXPECT_EQ(reader.metadata()[0].name, "recording");
  EXPECT_EQ(reader.metadata()[0].entries.at("robot"), "probe-1");

  const std::vector<Written> expected = InLogTimeOrder(written);
  const std::vector<Written> got = ReadAll(reader);
  ASSERT_EQ(got.size(), expected.size());
  for (size_t i = 0; i < got.size(); ++i) ASSERT_EQ(got[i], expected[i]) << "message " << i;

  const Statistics& stats = reader.statistics();
  EXPECT_EQ(stats.message_count, written.size());
  EXPECT_EQ(stats.schema_count, 2);
  EXPECT_EQ(stats.channel_count, 20u);
  EXPECT_EQ(stats.metadata_count, 1u);
  EXPECT_GT(stats.chunk_count, 20u);
  EXPECT_EQ(stats.message_start_time_ns, expected.front().log_time);
  EXPECT_EQ(stats.message_end_time_ns, expected.back().log_time);
  uint64_t counted = 0;
  for (const auto& [channel, count] : stats.channel_message_counts) counted += count;
  EXPECT_EQ(counted, written.size());

  // The scan path (no summary use) and the in-memory reader see the same.
  ReaderOptions scan;
  scan.force_scan = true;
  McapReader scanned(path, scan);
  EXPECT_FALSE(scanned.recovery().indexed);
  EXPECT_FALSE(scanned.truncated());
  EXPECT_EQ(ReadAll(scanned), expected);
  EXPECT_EQ(scanned.statistics(), stats);
  EXPECT_EQ(scanned.recovery().messages, written.size());
  const std::vector<std::byte> bytes = ReadFileBytes(path);
  McapReader memory = McapReader::FromBuffer("memory", bytes);
  EXPECT_EQ(ReadAll(memory), expected);
}

INSTANTIATE_TEST_SUITE_P(Compressions, RoundTripTest,
                         ::testing::Values(Compression::kNone, Compression::kZstd,
                                           Compression::kLz4),
                         [](const auto& info) {
                           return std::string(CompressionOptionName(info.param));
                         });

TEST(McapTest, FileLayoutFollowsTheSpec) {
  TempDir dir;
  const std::string path = dir.File("layout.mcap");
  WriterOptions options;
  options.compression = Compression::kLz4;
  options.chunk_size = 8 * 1024;
  WriteSample(path, options, 200);
  const std::vector<std::byte> file = ReadFileBytes(path);
  ASSERT_GT(file.size(), 16u);
  const std::string magic("\x89MCAP0\r\n", 8);
  EXPECT_EQ(std::memcmp(file.data(), magic.data(), 8), 0);
  EXPECT_EQ(std::memcmp(file.data() + file.size() - 8, magic.data(), 8), 0);

  const auto records = ListRecords(file);
  ASSERT_FALSE(records.empty());
  EXPECT_EQ(records.front().opcode, internal::kOpHeader);
  EXPECT_EQ(records.back().opcode, internal::kOpFooter);
  EXPECT_EQ(records.back().end() + 8, file.size());
  const auto chunks = RecordsWithOpcode(file, internal::kOpChunk);
  const auto chunk_indexes = RecordsWithOpcode(file, internal::kOpChunkIndex);
  const auto data_end = RecordsWithOpcode(file, internal::kOpDataEnd);
  EXPECT_GT(chunks.size(), 5u);
  EXPECT_EQ(chunk_indexes.size(), chunks.size());
  EXPECT_FALSE(RecordsWithOpcode(file, internal::kOpMessageIndex).empty());
  EXPECT_EQ(RecordsWithOpcode(file, internal::kOpStatistics).size(), 1u);
  EXPECT_EQ(RecordsWithOpcode(file, internal::kOpSummaryOffset).size(), 5u);  // 5 groups
  ASSERT_EQ(data_end.size(), 1u);

  // DataEnd holds the CRC of every byte before it.
  uint32_t stored = 0;
  std::memcpy(&stored, file.data() + data_end[0].offset + 9, 4);
  EXPECT_EQ(stored, internal::Crc32(file.data(), data_end[0].offset));
  // Footer: summary_start is right after DataEnd; the CRC covers summary..footer fields.
  const uint64_t footer = records.back().offset;
  const uint64_t summary_start = testing::LoadU64(file, footer + 9);
  EXPECT_EQ(summary_start, data_end[0].end());
  uint32_t summary_crc = 0;
  std::memcpy(&summary_crc, file.data() + footer + 9 + 16, 4);
  EXPECT_EQ(summary_crc,
            internal::Crc32(file.data() + summary_start, footer + 9 + 16 - summary_start));
}

TEST(McapTest, WriterOptionsChangeTheFileAndStayReadable) {
  TempDir dir;
  struct Case {
    const char* name;
    void (*apply)(WriterOptions&);
    uint8_t absent_opcode;
    bool indexed;
  };
  const Case cases[] = {
      {"no_message_indexes", [](WriterOptions& o) { o.write_message_indexes = false; },
       internal::kOpMessageIndex, true},
      {"no_chunk_indexes", [](WriterOptions& o) { o.write_chunk_indexes = false; },
       internal::kOpChunkIndex, false},
      {"no_statistics", [](WriterOptions& o) { o.write_statistics = false; },
       internal::kOpStatistics, false},
      {"no_summary_offsets", [](WriterOptions& o) { o.write_summary_offsets = false; },
       internal::kOpSummaryOffset, true},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    for (Compression compression : {Compression::kNone, Compression::kZstd}) {
      WriterOptions options;
      options.compression = compression;
      options.chunk_size = 4096;
      c.apply(options);
      const std::string path = dir.File(std::string(c.name) + ".mcap");
      const std::vector<Written> written = WriteSample(path, options, 150, 11);
      const std::vector<std::byte> file = ReadFileBytes(path);
      EXPECT_TRUE(RecordsWithOpcode(file, c.absent_opcode).empty());
      EXPECT_FALSE(RecordsWithOpcode(file, internal::kOpChunk).empty());
      McapReader reader(path);
      EXPECT_FALSE(reader.truncated());
      EXPECT_EQ(reader.recovery().indexed, c.indexed);
      EXPECT_EQ(ReadAll(reader), InLogTimeOrder(written));
      EXPECT_EQ(reader.statistics().message_count, written.size());
    }
  }
}

TEST(McapTest, WithoutCrcsEveryCrcFieldIsZero) {
  TempDir dir;
  const std::string path = dir.File("nocrc.mcap");
  WriterOptions options;
  options.write_crcs = false;
  options.compression = Compression::kNone;
  const std::vector<Written> written = WriteSample(path, options, 50);
  const std::vector<std::byte> file = ReadFileBytes(path);
  for (const auto& chunk : RecordsWithOpcode(file, internal::kOpChunk)) {
    uint32_t crc = 1;
    std::memcpy(&crc, file.data() + chunk.offset + 9 + 24, 4);
    EXPECT_EQ(crc, 0u);
  }
  const auto data_end = RecordsWithOpcode(file, internal::kOpDataEnd);
  ASSERT_EQ(data_end.size(), 1u);
  uint32_t crc = 1;
  std::memcpy(&crc, file.data() + data_end[0].offset + 9, 4);
  EXPECT_EQ(crc, 0u);
  McapReader reader(path);
  EXPECT_EQ(ReadAll(reader), InLogTimeOrder(written));
}

TEST(McapTest, EmptyFilesAreValid) {
  TempDir dir;
  for (Compression compression : {Compression::kNone, Compression::kZstd, Compression::kLz4}) {
    const std::string path = dir.File("empty.mcap");
    {
      WriterOptions options;
      options.compression = compression;
      McapWriter writer(path, options);
    }  // the destructor closes
    McapReader reader(path);
    EXPECT_FALSE(reader.truncated());
    EXPECT_TRUE(reader.schemas().empty());
    EXPECT_TRUE(reader.channels().empty());
    EXPECT_EQ(reader.statistics(), Statistics{});
    EXPECT_TRUE(ReadAll(reader).empty());

    // Schemas and channels but no message.
    {
      McapWriter writer(path);
      const uint16_t schema = writer.AddSchema("s", "ros2msg", "int8 x\n");
      writer.AddChannel("/quiet", "cdr", schema);
      writer.Close();
    }
    McapReader quiet(path);
    EXPECT_EQ(quiet.channels().size(), 1u);
    EXPECT_EQ(quiet.statistics().message_count, 0u);
    EXPECT_EQ(quiet.statistics().channel_count, 1u);
    EXPECT_TRUE(ReadAll(quiet).empty());
  }
}

TEST(McapTest, TopicAndTimeFilters) {
  TempDir dir;
  const std::string path = dir.File("filters.mcap");
  WriterOptions options;
  options.chunk_size = 2048;
  const std::vector<Written> written = WriteSample(path, options, 300);
  McapReader reader(path);
  const std::vector<Written> all = InLogTimeOrder(written);

  ReadOptions topics;
  topics.topics = {"/topic_3", "/topic_17"};
  std::vector<Written> expected;
  for (const Written& w : all) {
    if (w.topic == "/topic_3" || w.topic == "/topic_17") expected.push_back(w);
  }
  ASSERT_FALSE(expected.empty());
  EXPECT_EQ(ReadAll(reader, topics), expected);

  ReadOptions range;
  range.start_time_ns = all[40].log_time;
  range.end_time_ns = all[200].log_time;  // exclusive
  expected.clear();
  for (const Written& w : all) {
    if (w.log_time >= range.start_time_ns && w.log_time < range.end_time_ns) expected.push_back(w);
  }
  const std::vector<Written> got = ReadAll(reader, range);
  EXPECT_EQ(got, expected);
  ASSERT_FALSE(got.empty());
  EXPECT_EQ(got.front().log_time, range.start_time_ns);
  EXPECT_LT(got.back().log_time, range.end_time_ns);

  ReadOptions nothing;
  nothing.topics = {"/no_such_topic"};
  EXPECT_TRUE(ReadAll(reader, nothing).empty());
}

TEST(McapTest, TheDefaultRangeIncludesTheLargestLogTime) {
  TempDir dir;
  const std::string path = dir.File("max_time.mcap");
  {
    McapWriter writer(path);
    const uint16_t channel = writer.AddChannel("/t", "raw", 0);
    const std::string payload = "p";
    writer.Write(channel, 1, UINT64_MAX, 0, Bytes(payload));
    writer.Write(channel, 2, 0, 0, Bytes(payload));
  }
  McapReader reader(path);
  const auto all = ReadAll(reader);
  ASSERT_EQ(all.size(), 2u);
  EXPECT_EQ(all[0].log_time, 0u);
  EXPECT_EQ(all[1].log_time, UINT64_MAX);
  ReadOptions bounded;
  bounded.end_time_ns = UINT64_MAX - 1;
  EXPECT_EQ(ReadAll(reader, bounded).size(), 1u);
}

TEST(McapTest, ChunksOverlappingInTimeAreMergedInLogTimeOrder) {
  TempDir dir;
  const std::string path = dir.File("overlap.mcap");
  WriterOptions options;
  options.chunk_size = 1;  // one message per chunk
  std::vector<Written> written;
  {
    McapWriter writer(path, options);
    const uint16_t channel = writer.AddChannel("/t", "raw", 0);
    const uint64_t times[] = {50, 10, 30, 10, 60, 20, 50, 5};
    for (uint32_t i = 0; i < std::size(times); ++i) {
      Written w{"/t", i, times[i], 0, std::vector<std::byte>(1, std::byte(i))};
      writer.Write(channel, w.sequence, w.log_time, w.publish_time, w.data);
      written.push_back(w);
    }
  }
  McapReader reader(path);
  EXPECT_EQ(reader.statistics().chunk_count, 8u);
  const std::vector<Written> got = ReadAll(reader);
  EXPECT_EQ(got, InLogTimeOrder(written));
  std::vector<uint32_t> sequences;
  for (const Written& w : got) sequences.push_back(w.sequence);
  EXPECT_EQ(sequences, (std::vector<uint32_t>{7, 1, 3, 5, 2, 0, 6, 4}));
}

TEST(McapTest, WriterErrorsNameThePathAndTheProblem) {
  TempDir dir;
  const std::string path = dir.File("errors.mcap");
  McapWriter writer(path);
  const std::string payload = "x";
  PROBELESS_EXPECT_THROWS_MESSAGE(writer.Write(3, 0, 0, 0, Bytes(payload)), LogError,
                                  path + ": Write to unknown channel id 3");
  PROBELESS_EXPECT_THROWS_MESSAGE(writer.AddChannel("/a", "cdr", 9), LogError,
                                  path + ": AddChannel '/a': unknown schema id 9");
  PROBELESS_EXPECT_THROWS_MESSAGE(writer.AddChannel("", "cdr", 0), LogError,
                                  path + ": AddChannel: empty topic");
  writer.Close();
  writer.Close();  // idempotent
  PROBELESS_EXPECT_THROWS_MESSAGE(writer.AddSchema("s", "e", "d"), LogError,
                                  path + ": AddSchema after Close()");

  WriterOptions zero_chunk;
  zero_chunk.chunk_size = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      McapWriter bad(dir.File("zero.mcap"), zero_chunk), LogError,
      dir.File("zero.mcap") + ": WriterOptions::chunk_size must be > 0");
  WriterOptions bad_level;
  bad_level.compression = Compression::kLz4;
  bad_level.compression_level = 99;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      McapWriter bad(dir.File("level.mcap"), bad_level), LogError,
      dir.File("level.mcap") + ": lz4 compression level 99 out of range 0..12");
  const std::string missing = dir.File("no/such/dir/x.mcap");
  PROBELESS_EXPECT_THROWS_MESSAGE(McapWriter bad(missing), LogError,
                                  missing + ": cannot create: No such file or directory");
}

// ---- Reader errors on corrupt input ----

std::string ReadError(const std::string& path, const ReaderOptions& options = {}) {
  return probeless::testing::ThrownMessage<LogError>([&] {
    McapReader reader(path, options);
    ReadAll(reader);
  });
}

TEST(McapReaderErrors, MissingEmptyAndNonMcapFiles) {
  TempDir dir;
  const std::string missing = dir.File("missing.mcap");
  EXPECT_EQ(ReadError(missing), missing + ": cannot open: No such file or directory");
  const std::string empty = dir.File("empty.mcap");
  WriteFileBytes(empty, {});
  EXPECT_EQ(ReadError(empty),
            empty + ": offset 0: file of 0 bytes is too short for the MCAP magic");
  const std::string text = dir.File("text.mcap");
  const std::string content = "this is not an MCAP file at all";
  WriteFileBytes(text, Bytes(content));
  EXPECT_EQ(ReadError(text), text + ": offset 0: bad magic (not an MCAP file)");
  EXPECT_EQ(ReadError(dir.File("")), dir.File("") + ": not a regular file");
}

// A complete uncompressed file and the offset of its first chunk.
struct Sample {
  std::string path;
  std::vector<std::byte> bytes;
  std::vector<Written> written;
};

Sample MakeSample(const TempDir& dir, Compression compression, const std::string& name) {
  Sample sample;
  sample.path = dir.File(name);
  WriterOptions options;
  options.compression = compression;
  options.chunk_size = 4096;
  sample.written = WriteSample(sample.path, options, 100);
  sample.bytes = ReadFileBytes(sample.path);
  return sample;
}

TEST(McapReaderErrors, FlippedChunkByteIsACrcMismatch) {
  TempDir dir;
  Sample sample = MakeSample(dir, Compression::kNone, "crc.mcap");
  const auto chunks = RecordsWithOpcode(sample.bytes, internal::kOpChunk);
  ASSERT_GT(chunks.size(), 2u);
  const auto& chunk = chunks[1];
  sample.bytes[chunk.end() - 5] ^= std::byte{0x40};  // inside the last message's data
  WriteFileBytes(sample.path, sample.bytes);
  const std::string prefix = sample.path + ": offset " + std::to_string(chunk.offset) + ": ";
  EXPECT_THAT(ReadError(sample.path),
              MatchesRegex(prefix + "Chunk record: CRC mismatch \\(stored 0x[0-9a-f]{8}, "
                                    "computed 0x[0-9a-f]{8}\\)"));
  ReaderOptions scan;
  scan.force_scan = true;
  EXPECT_THAT(ReadError(sample.path, scan), MatchesRegex(prefix + "Chunk record: CRC mismatch.*"));
  // Without CRC checks the same file reads (the flipped byte is message data).
  ReaderOptions no_crc;
  no_crc.verify_crcs = false;
  McapReader reader(sample.path, no_crc);
  EXPECT_EQ(ReadAll(reader).size(), sample.written.size());
}

TEST(McapReaderErrors, CorruptCompressedChunks) {
  TempDir dir;
  for (Compression compression : {Compression::kZstd, Compression::kLz4}) {
    Sample sample = MakeSample(dir, compression, "compressed.mcap");
    const auto chunk = RecordsWithOpcode(sample.bytes, internal::kOpChunk)[0];
    for (uint64_t at = chunk.end() - 40; at < chunk.end() - 20; ++at)
      sample.bytes[at] ^= std::byte{0x5a};
    WriteFileBytes(sample.path, sample.bytes);
    EXPECT_THAT(ReadError(sample.path),
                MatchesRegex(sample.path + ": offset " + std::to_string(chunk.offset) +
                             ": Chunk record: (" + std::string(CompressionName(compression)) +
                             " .*|CRC mismatch .*)"));
  }
}

TEST(McapReaderErrors, SummaryCrcAndFooterOffsets) {
  TempDir dir;
  Sample sample = MakeSample(dir, Compression::kLz4, "summary.mcap");
  const auto chunk_index = RecordsWithOpcode(sample.bytes, internal::kOpChunkIndex)[0];
  const uint64_t footer = sample.bytes.size() - 8 - 29;
  std::vector<std::byte> flipped = sample.bytes;
  flipped[chunk_index.offset + 12] ^= std::byte{1};
  WriteFileBytes(sample.path, flipped);
  EXPECT_THAT(ReadError(sample.path),
              MatchesRegex(sample.path + ": offset " + std::to_string(footer + 9 + 16) +
                           ": Footer: summary CRC mismatch \\(stored 0x[0-9a-f]{8}, computed "
                           "0x[0-9a-f]{8}\\)"));

  // summary_start beyond the footer (CRC off so the offset check is what fires).
  std::vector<std::byte> bad_start = sample.bytes;
  const uint64_t huge = uint64_t{1} << 40;
  std::memcpy(bad_start.data() + footer + 9, &huge, 8);
  std::memset(bad_start.data() + footer + 9 + 16, 0, 4);
  WriteFileBytes(sample.path, bad_start);
  EXPECT_EQ(ReadError(sample.path), sample.path + ": offset " + std::to_string(footer + 9) +
                                        ": Footer: summary_start " + std::to_string(huge) +
                                        " outside the file's data (" +
                                        std::to_string(ListRecords(sample.bytes)[0].end()) + ".." +
                                        std::to_string(footer) + ")");
}

TEST(McapReaderErrors, BadLengths) {
  TempDir dir;
  Sample sample = MakeSample(dir, Compression::kNone, "lengths.mcap");
  const auto chunk = RecordsWithOpcode(sample.bytes, internal::kOpChunk)[0];
  std::vector<std::byte> bytes = sample.bytes;
  const uint64_t absurd = uint64_t{1} << 50;
  std::memcpy(bytes.data() + chunk.offset + 1, &absurd, 8);
  WriteFileBytes(sample.path, bytes);
  EXPECT_EQ(ReadError(sample.path), sample.path + ": offset " + std::to_string(chunk.offset) +
                                        ": Chunk record length " + std::to_string(absurd) +
                                        " does not match its ChunkIndex (" +
                                        std::to_string(chunk.length) + ")");
  ReaderOptions scan;
  scan.force_scan = true;
  const uint64_t footer = sample.bytes.size() - 8 - 29;
  EXPECT_EQ(ReadError(sample.path, scan),
            sample.path + ": offset " + std::to_string(chunk.offset) + ": Chunk record length " +
                std::to_string(absurd) + " runs past the data section (" +
                std::to_string(footer - chunk.offset - 9) + " bytes left)");

  // A message record inside the chunk whose length runs past the chunk (CRC off to reach it).
  bytes = sample.bytes;
  const uint64_t records_at = chunk.offset + 9 + 8 + 8 + 8 + 4 + 4 + 0 + 8;  // compression ""
  ASSERT_EQ(static_cast<uint8_t>(bytes[records_at]), internal::kOpMessage);
  const uint64_t long_message = 1'000'000;
  std::memcpy(bytes.data() + records_at + 1, &long_message, 8);
  WriteFileBytes(sample.path, bytes);
  ReaderOptions no_crc;
  no_crc.verify_crcs = false;
  EXPECT_THAT(ReadError(sample.path, no_crc),
              MatchesRegex(sample.path + ": offset " + std::to_string(chunk.offset) +
                           ": chunk byte 0: Message record length 1000000 runs past the end of "
                           "the chunk \\([0-9]+ bytes left\\)"));
}

// Hand-made files: magic, Header, the given data-section records, DataEnd, empty Footer, magic.
std::vector<std::byte> Craft(const std::vector<uint8_t>& data_records) {
  std::vector<uint8_t> out(internal::kMagic, internal::kMagic + 8);
  internal::AppendHeader(out, "", "test");
  out.insert(out.end(), data_records.begin(), data_records.end());
  internal::AppendDataEnd(out, 0);
  internal::AppendFooter(out, 0, 0, 0);
  out.insert(out.end(), internal::kMagic, internal::kMagic + 8);
  std::vector<std::byte> bytes(out.size());
  std::memcpy(bytes.data(), out.data(), out.size());
  return bytes;
}

std::vector<uint8_t> ChannelRecord(uint16_t id) {
  std::vector<uint8_t> out;
  internal::AppendChannel(out, Channel{id, 0, "/t", "raw", {}});
  return out;
}

std::vector<uint8_t> MessageRecord(uint16_t channel, uint64_t time, const std::string& data) {
  std::vector<uint8_t> out;
  const size_t begin = internal::BeginRecord(out, internal::kOpMessage);
  internal::Put<uint16_t>(out, channel);
  internal::Put<uint32_t>(out, 1);
  internal::Put<uint64_t>(out, time);
  internal::Put<uint64_t>(out, time);
  internal::PutBytes(out, data.data(), data.size());
  internal::EndRecord(out, begin);
  return out;
}

std::vector<uint8_t> ChunkRecord(const std::string& compression, uint64_t start, uint64_t end,
                                 const std::vector<uint8_t>& records,
                                 uint64_t uncompressed_size = UINT64_MAX) {
  std::vector<uint8_t> out;
  internal::ChunkHeader header;
  header.message_start_time = start;
  header.message_end_time = end;
  header.uncompressed_size = uncompressed_size == UINT64_MAX ? records.size() : uncompressed_size;
  header.uncompressed_crc = 0;
  header.compression = compression;
  header.records_size = records.size();
  internal::AppendChunkHeader(out, header);
  out.insert(out.end(), records.begin(), records.end());
  return out;
}

std::vector<uint8_t> Concat(std::initializer_list<std::vector<uint8_t>> parts) {
  std::vector<uint8_t> out;
  for (const auto& part : parts) out.insert(out.end(), part.begin(), part.end());
  return out;
}

TEST(McapReaderErrors, CraftedChunkProblems) {
  TempDir dir;
  const std::string path = dir.File("crafted.mcap");
  const uint64_t chunk_at = 8 + 9 + 4 + 0 + 4 + 4;  // after magic and Header("", "test")
  const std::string at = path + ": offset " + std::to_string(chunk_at) + ": ";

  // A valid crafted file first, to show the crafting is right: loose and chunked messages.
  WriteFileBytes(
      path,
      Craft(Concat(
          {ChannelRecord(1), MessageRecord(1, 5, "loose"),
           ChunkRecord("", 7, 9, Concat({MessageRecord(1, 9, "b"), MessageRecord(1, 7, "a")}))})));
  {
    McapReader reader(path);
    EXPECT_FALSE(reader.truncated());
    const auto got = ReadAll(reader);
    ASSERT_EQ(got.size(), 3u);
    EXPECT_EQ(got[0].log_time, 5u);
    EXPECT_EQ(got[1].log_time, 7u);
    EXPECT_EQ(got[2].log_time, 9u);
  }

  WriteFileBytes(
      path, Craft(Concat({ChunkRecord("brotli", 1, 1,
                                      Concat({ChannelRecord(1), MessageRecord(1, 1, "x")}))})));
  EXPECT_EQ(ReadError(path), at + "Chunk record: unknown chunk compression 'brotli' (supported: "
                                  "'', 'zstd', 'lz4')");

  WriteFileBytes(path, Craft(Concat({ChunkRecord("zstd", 1, 1, {1, 2, 3, 4}, uint64_t{1} << 40)})));
  EXPECT_EQ(ReadError(path), at + "Chunk record: uncompressed size 1099511627776 exceeds the limit "
                                  "of 1073741824 bytes");

  WriteFileBytes(
      path,
      Craft(Concat({ChunkRecord("", 1, 1, Concat({ChannelRecord(1), MessageRecord(2, 1, "x")}))})));
  EXPECT_THAT(ReadError(path), MatchesRegex(at + "chunk byte [0-9]+: Message record on unknown "
                                                 "channel id 2"));

  WriteFileBytes(path, Craft(Concat({ChunkRecord(
                           "", 10, 20, Concat({ChannelRecord(1), MessageRecord(1, 25, "x")}))})));
  EXPECT_THAT(ReadError(path), MatchesRegex(at + "chunk byte [0-9]+: Message record log time 25 "
                                                 "outside the chunk's range 10..20"));

  WriteFileBytes(path, Craft(Concat({ChunkRecord("", 20, 10, {})})));
  EXPECT_EQ(ReadError(path), at + "Chunk record: message_start_time 20 after message_end_time 10");

  WriteFileBytes(path, Craft(Concat({ChunkRecord("", 1, 1, {}, 5)})));
  EXPECT_EQ(ReadError(path),
            at + "Chunk record: uncompressed chunk with 0 bytes of records declares 5");

  WriteFileBytes(path, Craft(Concat({ChunkRecord("lz4", 1, 1, {1, 2, 3, 4, 5, 6, 7, 8}, 100)})));
  EXPECT_THAT(ReadError(path), MatchesRegex(at + "Chunk record: lz4 decompression failed: .*"));

  WriteFileBytes(path, Craft(Concat({MessageRecord(4, 1, "x")})));
  EXPECT_EQ(ReadError(path), at + "Message record on unknown channel id 4");

  std::vector<uint8_t> short_channel;
  internal::BeginRecord(short_channel, internal::kOpChannel);
  internal::Put<uint16_t>(short_channel, 1);
  internal::Put<uint16_t>(short_channel, 0);
  internal::Put<uint32_t>(short_channel, 500);  // topic of 500 bytes in a 2-byte body rest
  internal::EndRecord(short_channel, 0);
  WriteFileBytes(path, Craft(short_channel));
  EXPECT_EQ(ReadError(path), path + ": offset " + std::to_string(chunk_at + 9 + 8) +
                                 ": Channel record: field 'topic' needs 500 bytes, only 0 left "
                                 "in the record");

  std::vector<uint8_t> zero_schema;
  internal::AppendSchema(zero_schema, Schema{0, "s", "e", "d"});
  WriteFileBytes(path, Craft(zero_schema));
  EXPECT_EQ(ReadError(path), at + "Schema record with the reserved id 0");
}

TEST(McapReaderErrors, DataSectionCrcIsCheckedWhenScanning) {
  TempDir dir;
  Sample sample = MakeSample(dir, Compression::kZstd, "datacrc.mcap");
  const auto channel = RecordsWithOpcode(sample.bytes, internal::kOpChannel)[0];
  // Flip a byte of the channel's metadata value (still parses, but the data CRC differs).
  sample.bytes[channel.end() - 1] ^= std::byte{0x01};
  WriteFileBytes(sample.path, sample.bytes);
  const auto data_end = RecordsWithOpcode(sample.bytes, internal::kOpDataEnd)[0];
  ReaderOptions scan;
  scan.force_scan = true;
  EXPECT_THAT(ReadError(sample.path, scan),
              MatchesRegex(sample.path + ": offset " + std::to_string(data_end.offset) +
                           ": DataEnd: data section CRC mismatch \\(stored 0x[0-9a-f]{8}, "
                           "computed 0x[0-9a-f]{8}\\)"));
}

TEST(McapReaderErrors, AbsurdChunkIndexSizes) {
  TempDir dir;
  Sample sample = MakeSample(dir, Compression::kNone, "index.mcap");
  ReaderOptions small;
  small.max_chunk_bytes = 1000;  // every chunk of this file is bigger
  EXPECT_THAT(ReadError(sample.path, small),
              MatchesRegex(sample.path + ": offset [0-9]+: ChunkIndex 0: uncompressed size "
                                         "[0-9]+ exceeds the limit of 1000 bytes"));
}

}  // namespace
}  // namespace probeless::log

namespace probeless::log {
namespace {

TEST(Crc32Test, MatchesTheZlibCheckValueAndCombines) {
  const std::string check = "123456789";
  EXPECT_EQ(internal::Crc32(check.data(), check.size()), 0xCBF43926u);
  EXPECT_EQ(internal::Crc32("", 0), 0u);
  std::mt19937_64 rng(5);
  const std::vector<std::byte> data = testing::RandomBytes(rng, 100'000);
  const uint32_t whole = internal::Crc32(data.data(), data.size());
  uint32_t pieces = 0;
  for (size_t at = 0; at < data.size();) {
    const size_t n = std::min<size_t>(data.size() - at, rng() % 9000);
    pieces = internal::Crc32Update(pieces, data.data() + at, n);
    at += n;
  }
  EXPECT_EQ(pieces, whole);
  for (size_t split :
       {size_t{0}, size_t{1}, size_t{7}, size_t{4096}, size_t{99'999}, data.size()}) {
    const uint32_t a = internal::Crc32(data.data(), split);
    const uint32_t b = internal::Crc32(data.data() + split, data.size() - split);
    EXPECT_EQ(internal::Crc32Combine(a, b, data.size() - split), whole) << split;
  }
}

}  // namespace
}  // namespace probeless::log
