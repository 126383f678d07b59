// Little-endian serialisation helpers and a bounds-checked parser for MCAP records.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/log/mcap.h"

namespace probeless::log::internal {

static_assert(std::endian::native == std::endian::little,
              "probeless::log assumes a little-endian host (MCAP and CDR-LE are little-endian)");

// Appends raw bytes.
inline void PutBytes(std::vector<uint8_t>& out, const void* data, size_t size) {
  if (size == 0) return;
  const size_t at = out.size();
  out.resize(at + size);
  std::memcpy(out.data() + at, data, size);
}

// Appends an integer little-endian.
template <class T>
void Put(std::vector<uint8_t>& out, T value) {
  PutBytes(out, &value, sizeof(T));
}

// MCAP String: uint32 byte length then the bytes.
inline void PutString(std::vector<uint8_t>& out, std::string_view text) {
  Put<uint32_t>(out, static_cast<uint32_t>(text.size()));
  PutBytes(out, text.data(), text.size());
}

// Overwrites a little-endian integer at `at`.
template <class T>
void PutAt(std::vector<uint8_t>& out, size_t at, T value) {
  std::memcpy(out.data() + at, &value, sizeof(T));
}

template <class T>
T Load(const uint8_t* p) {
  T value;
  std::memcpy(&value, p, sizeof(T));
  return value;
}

// Where parsed bytes come from, for error messages.
struct Where {
  const std::string* path = nullptr;
  // File offset of the parsed span's first byte; for chunk contents, the Chunk record's offset.
  uint64_t base = 0;
  // The span holds a chunk's uncompressed records (positions are reported inside the chunk).
  bool in_chunk = false;
};

// "<path>: offset <n>: " for byte `position` of the span described by `where`.
inline std::string ErrorPrefix(const Where& where, uint64_t position) {
  if (where.in_chunk) {
    return *where.path + ": offset " + std::to_string(where.base) + ": chunk byte " +
           std::to_string(position) + ": ";
  }
  return *where.path + ": offset " + std::to_string(where.base + position) + ": ";
}

[[noreturn]] inline void Fail(const Where& where, uint64_t position, const std::string& problem) {
  throw LogError(ErrorPrefix(where, position) + problem);
}

// Reads the fields of one record body; every read is bounds-checked and a failure throws
// LogError "<path>: offset <field offset>: <record>: field '<field>' ...".
class Parser {
 public:
  // `report_base` is added to positions in error messages (where data[0] sits in the span that
  // `where` describes).
  Parser(std::span<const uint8_t> data, Where where, size_t start_position, std::string_view record,
         uint64_t report_base = 0)
      : data_(data),
        where_(where),
        position_(start_position),
        record_(record),
        report_base_(report_base) {}

  template <class T>
  T Get(std::string_view field) {
    Need(sizeof(T), field);
    const T value = Load<T>(data_.data() + position_);
    position_ += sizeof(T);
    return value;
  }
  uint8_t U8(std::string_view field) { return Get<uint8_t>(field); }
  uint16_t U16(std::string_view field) { return Get<uint16_t>(field); }
  uint32_t U32(std::string_view field) { return Get<uint32_t>(field); }
  uint64_t U64(std::string_view field) { return Get<uint64_t>(field); }

  std::span<const uint8_t> Bytes(uint64_t size, std::string_view field) {
    Need(size, field);
    const auto bytes = data_.subspan(position_, static_cast<size_t>(size));
    position_ += static_cast<size_t>(size);
    return bytes;
  }
  // uint32 length then bytes (MCAP String, Bytes, Map and Array prefixes).
  std::span<const uint8_t> U32Prefixed(std::string_view field) {
    const uint32_t size = U32(field);
    return Bytes(size, field);
  }
  std::span<const uint8_t> U64Prefixed(std::string_view field) {
    const uint64_t size = U64(field);
    return Bytes(size, field);
  }
  std::string String(std::string_view field) {
    const auto bytes = U32Prefixed(field);
    return std::string(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  }
  // The rest of the span.
  std::span<const uint8_t> Rest() {
    const auto bytes = data_.subspan(position_);
    position_ = data_.size();
    return bytes;
  }

  size_t position() const { return position_; }
  // The position as reported in errors.
  uint64_t reported_position() const { return report_base_ + position_; }
  size_t remaining() const { return data_.size() - position_; }
  const Where& where() const { return where_; }

  [[noreturn]] void FailHere(const std::string& problem) const {
    Fail(where_, report_base_ + position_, std::string(record_) + ": " + problem);
  }

 private:
  void Need(uint64_t size, std::string_view field) {
    if (size > remaining()) {
      FailHere("field '" + std::string(field) + "' needs " + std::to_string(size) +
               " bytes, only " + std::to_string(remaining()) + " left in the record");
    }
  }

  std::span<const uint8_t> data_;
  Where where_;
  size_t position_;
  std::string record_;  // owned: callers pass temporaries such as OpcodeName(op) + " record"
  uint64_t report_base_;
};

}  // namespace probeless::log::internal
