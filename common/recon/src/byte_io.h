// Internal: appending plain values to a byte buffer and reading them back with bounds checks, for
// the fusion checkpoint (checkpoint.h). Values keep this machine's representation (x86-64:
// little-endian, IEEE 754); the checkpoint's header records it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "probeless/recon/math.h"

namespace probeless::recon::detail {

class ByteWriter {
 public:
  explicit ByteWriter(std::vector<std::byte>& out) : out_(out) {}
  template <class T>
  void Put(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    PutBytes(&value, sizeof(T));
  }
  void PutBytes(const void* data, size_t bytes) {
    const size_t at = out_.size();
    out_.resize(at + bytes);
    std::memcpy(out_.data() + at, data, bytes);
  }

 private:
  std::vector<std::byte>& out_;
};

// Reads from `in`; every read past the end throws ReconError "<name>: truncated at byte N
// (expected M more)".
class ByteReader {
 public:
  ByteReader(std::span<const std::byte> in, std::string name) : in_(in), name_(std::move(name)) {}
  template <class T>
  T Get() {
    static_assert(std::is_trivially_copyable_v<T>);
    T value;
    GetBytes(&value, sizeof(T));
    return value;
  }
  void GetBytes(void* out, size_t bytes) {
    Need(bytes);
    std::memcpy(out, in_.data() + at_, bytes);
    at_ += bytes;
  }
  // Throws the truncation error unless `bytes` more are left.
  void Need(size_t bytes) const {
    if (in_.size() - at_ < bytes) {
      throw ReconError(name_ + ": truncated at byte " + std::to_string(in_.size()) + " (expected " +
                       std::to_string(bytes - (in_.size() - at_)) + " more)");
    }
  }
  size_t offset() const { return at_; }
  size_t remaining() const { return in_.size() - at_; }
  const std::string& name() const { return name_; }

 private:
  std::span<const std::byte> in_;
  std::string name_;
  size_t at_ = 0;
};

// FNV-1a over 64-bit words (the last bytes one by one): a checksum against corrupt files, fast
// enough for tens of megabytes per checkpoint.
inline uint64_t Checksum(std::span<const std::byte> bytes) {
  constexpr uint64_t kPrime = 0x100000001b3ull;
  uint64_t h = 0xcbf29ce484222325ull;
  size_t i = 0;
  for (; i + 8 <= bytes.size(); i += 8) {
    uint64_t word;
    std::memcpy(&word, bytes.data() + i, 8);
    h = (h ^ word) * kPrime;
  }
  for (; i < bytes.size(); ++i) h = (h ^ static_cast<uint64_t>(bytes[i])) * kPrime;
  return h;
}

}  // namespace probeless::recon::detail
