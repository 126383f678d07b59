// CDR (OMG XCDR1, little-endian: the ROS 2 wire format) writer and reader.
//
// A buffer starts with the 4-byte encapsulation header 00 01 00 00 (CDR_LE, no options). After it,
// every primitive of size n (1, 2, 4 or 8 bytes) starts at an offset that is a multiple of n,
// counted from the first byte after the encapsulation header; padding bytes are zero. bool and
// uint8/int8 take 1 byte; a string is a uint32 length that counts the terminating NUL, the
// characters and the NUL; a sequence (T[]) is a uint32 element count then the elements; a fixed
// array (T[N]) is the N elements with no count. Nested structs are their fields in order, with no
// padding of their own beyond their fields' alignment.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "probeless/log/mcap.h"

namespace probeless::log {

// Bad CDR input or a message that cannot be converted. what() is one line naming the type, the
// field and the byte offset, e.g.
// "CDR sensor_msgs/msg/Image: field 'data' at offset 52: 921600 bytes needed, only 100 left".
class CdrError : public LogError {
 public:
  using LogError::LogError;
};

// The CDR primitive types (arithmetic types of size 1, 2, 4 or 8).
template <class T>
concept CdrPrimitive = std::is_arithmetic_v<T> &&
    (sizeof(T) == 1 || sizeof(T) == 2 || sizeof(T) == 4 || sizeof(T) == 8);

class CdrWriter {
 public:
  // Starts a buffer holding just the encapsulation header.
  CdrWriter();

  // Back to just the encapsulation header (the capacity is kept).
  void Reset();
  // Reserves room for `bytes` bytes of body.
  void Reserve(size_t bytes) { buffer_.reserve(buffer_.size() + bytes); }

  // A primitive, aligned to its size.
  template <CdrPrimitive T>
  void Write(T value) {
    Align(sizeof(T));
    Append(&value, sizeof(T));
  }
  void Bool(bool value) { Write<uint8_t>(value ? 1 : 0); }
  // A string: uint32 length (characters + 1), the characters, NUL.
  void String(std::string_view text);
  // A fixed array T[N]: the elements, aligned, no count.
  template <CdrPrimitive T>
  void Array(std::span<const T> values) {
    Align(sizeof(T));
    Append(values.data(), values.size_bytes());
  }
  // A sequence T[]: uint32 count, then the elements.
  template <CdrPrimitive T>
  void Sequence(std::span<const T> values) {
    Write<uint32_t>(static_cast<uint32_t>(values.size()));
    Array(values);
  }
  // A uint8[] sequence from raw bytes.
  void ByteSequence(std::span<const std::byte> bytes);

  // The whole buffer, encapsulation header included.
  std::span<const std::byte> data() const { return buffer_; }
  size_t size() const { return buffer_.size(); }
  // Moves the buffer out (the writer is Reset()).
  std::vector<std::byte> Take();

 private:
  void Align(size_t alignment);
  void Append(const void* bytes, size_t size);

  std::vector<std::byte> buffer_;
};

class CdrReader {
 public:
  // Checks the encapsulation header: CDR_LE (00 01) is accepted; CDR_BE (00 00) and other
  // representations (XCDR2, PL_CDR) throw CdrError. `type` names the message type in errors.
  CdrReader(std::span<const std::byte> data, std::string_view type);

  template <CdrPrimitive T>
  T Read(std::string_view field) {
    Align(sizeof(T));
    Need(sizeof(T), field);
    T value;
    std::memcpy(&value, data_.data() + position_, sizeof(T));
    position_ += sizeof(T);
    return value;
  }
  // A bool; bytes other than 0 and 1 throw CdrError.
  bool Bool(std::string_view field);
  // A string; throws CdrError unless its length is at least 1, fits and ends in NUL.
  std::string String(std::string_view field);
  // A fixed array into `out`.
  template <CdrPrimitive T>
  void Array(std::span<T> out, std::string_view field) {
    Align(sizeof(T));
    Need(out.size_bytes(), field);
    if (!out.empty()) std::memcpy(out.data(), data_.data() + position_, out.size_bytes());
    position_ += out.size_bytes();
  }
  // A sequence's elements as raw little-endian bytes (count * sizeof(T) bytes, a view into the
  // input, not necessarily aligned in memory). Throws CdrError if they do not fit in the input,
  // so the count is always bounded by the input size.
  template <CdrPrimitive T>
  std::span<const std::byte> SequenceBytes(std::string_view field) {
    const uint32_t count = Read<uint32_t>(field);
    Align(sizeof(T));
    const uint64_t bytes = uint64_t{count} * sizeof(T);
    Need(bytes, field);
    const auto view = data_.subspan(position_, static_cast<size_t>(bytes));
    position_ += static_cast<size_t>(bytes);
    return view;
  }
  // A sequence copied into a vector (bounded by the input size, see SequenceBytes).
  template <CdrPrimitive T>
  std::vector<T> Sequence(std::string_view field) {
    const auto bytes = SequenceBytes<T>(field);
    std::vector<T> values(bytes.size() / sizeof(T));
    if (!values.empty()) std::memcpy(values.data(), bytes.data(), bytes.size());
    return values;
  }

  // Offset of the next byte from the start of the buffer (encapsulation header included).
  size_t position() const { return position_; }
  size_t remaining() const { return position_ >= data_.size() ? 0 : data_.size() - position_; }
  // Throws CdrError "<type>: field '<field>': <problem>" at the current offset.
  [[noreturn]] void Fail(std::string_view field, const std::string& problem) const;

 private:
  void Align(size_t alignment);
  void Need(uint64_t bytes, std::string_view field) const;

  std::span<const std::byte> data_;
  std::string type_;
  size_t position_ = 0;
};

}  // namespace probeless::log
