// Helpers shared by the probeless_log tests (common/log/*_test.cpp and tests/log/).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "probeless/log/mcap_reader.h"
#include "probeless/log/mcap_writer.h"
#include "probeless/testing/testing.h"

namespace probeless::log::testing {

// A fresh directory for one test, removed at the end (path(), File(name)).
class TempDir : public probeless::testing::TempDir {
 public:
  TempDir() : probeless::testing::TempDir("probeless_log") {}
  // `name` under the directory; parent folders are NOT created (tests write to missing folders).
  std::string File(const std::string& name) const {
    return (std::filesystem::path(path()) / name).string();
  }
};

inline std::vector<std::byte> ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<char> chars((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::vector<std::byte> bytes(chars.size());
  for (size_t i = 0; i < chars.size(); ++i) bytes[i] = static_cast<std::byte>(chars[i]);
  return bytes;
}

inline void WriteFileBytes(const std::string& path, std::span<const std::byte> bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
}

// One message as written, for comparisons.
struct Written {
  std::string topic;
  uint32_t sequence = 0;
  uint64_t log_time = 0;
  uint64_t publish_time = 0;
  std::vector<std::byte> data;
  bool operator==(const Written&) const = default;
};

inline std::vector<std::byte> RandomBytes(std::mt19937_64& rng, size_t size) {
  std::vector<std::byte> bytes(size);
  for (size_t i = 0; i < size; ++i) bytes[i] = static_cast<std::byte>(rng() & 0xFF);
  return bytes;
}

// Every message of `reader` (selected by `options`), in cursor order.
inline std::vector<Written> ReadAll(const McapReader& reader, const ReadOptions& options = {}) {
  std::vector<Written> out;
  MessageCursor cursor = reader.Messages(options);
  MessageView message;
  while (cursor.Next(message)) {
    out.push_back(Written{message.channel->topic, message.sequence, message.log_time_ns,
                          message.publish_time_ns,
                          std::vector<std::byte>(message.data.begin(), message.data.end())});
  }
  return out;
}

// `written` sorted as a reader returns them: by log time, ties in write order.
inline std::vector<Written> InLogTimeOrder(std::vector<Written> written) {
  std::stable_sort(written.begin(), written.end(),
                   [](const Written& a, const Written& b) { return a.log_time < b.log_time; });
  return written;
}

}  // namespace probeless::log::testing

namespace probeless::log::testing {

// A top-level record of a file.
struct RecordInfo {
  uint64_t offset = 0;  // of the opcode
  uint8_t opcode = 0;
  uint64_t length = 0;  // body length
  uint64_t end() const { return offset + 9 + length; }
};

inline uint64_t LoadU64(std::span<const std::byte> bytes, uint64_t at) {
  uint64_t value = 0;
  std::memcpy(&value, bytes.data() + at, 8);
  return value;
}

// The top-level records after the magic, up to the Footer (or the last complete record).
inline std::vector<RecordInfo> ListRecords(std::span<const std::byte> file) {
  std::vector<RecordInfo> records;
  uint64_t at = 8;
  while (at + 9 <= file.size()) {
    RecordInfo record{at, static_cast<uint8_t>(file[at]), LoadU64(file, at + 1)};
    if (record.length > file.size() - at - 9) break;
    records.push_back(record);
    at = record.end();
    if (record.opcode == 0x02) break;  // Footer
  }
  return records;
}

inline std::vector<RecordInfo> RecordsWithOpcode(std::span<const std::byte> file, uint8_t opcode) {
  std::vector<RecordInfo> out;
  for (const RecordInfo& record : ListRecords(file)) {
    if (record.opcode == opcode) out.push_back(record);
  }
  return out;
}

}  // namespace probeless::log::testing
