#include "probeless/log/cdr.h"

#include <cstdio>

namespace probeless::log {
namespace {

constexpr size_t kEncapsulationSize = 4;
constexpr std::byte kCdrLe[kEncapsulationSize] = {std::byte{0x00}, std::byte{0x01}, std::byte{0x00},
                                                  std::byte{0x00}};

}  // namespace

CdrWriter::CdrWriter() { Reset(); }

void CdrWriter::Reset() {
  buffer_.resize(kEncapsulationSize);
  std::memcpy(buffer_.data(), kCdrLe, kEncapsulationSize);
}

void CdrWriter::Align(size_t alignment) {
  const size_t misalignment = (buffer_.size() - kEncapsulationSize) % alignment;
  if (misalignment != 0) buffer_.resize(buffer_.size() + alignment - misalignment, std::byte{0});
}

void CdrWriter::Append(const void* bytes, size_t size) {
  if (size == 0) return;
  const size_t at = buffer_.size();
  buffer_.resize(at + size);
  std::memcpy(buffer_.data() + at, bytes, size);
}

void CdrWriter::String(std::string_view text) {
  Write<uint32_t>(static_cast<uint32_t>(text.size() + 1));
  Append(text.data(), text.size());
  buffer_.push_back(std::byte{0});
}

void CdrWriter::ByteSequence(std::span<const std::byte> bytes) {
  Write<uint32_t>(static_cast<uint32_t>(bytes.size()));
  Append(bytes.data(), bytes.size());
}

std::vector<std::byte> CdrWriter::Take() {
  std::vector<std::byte> out = std::move(buffer_);
  buffer_ = {};
  Reset();
  return out;
}

CdrReader::CdrReader(std::span<const std::byte> data, std::string_view type)
    : data_(data), type_(type) {
  if (data.size() < kEncapsulationSize) {
    throw CdrError("CDR " + type_ + ": " + std::to_string(data.size()) +
                   " bytes are too few for the encapsulation header");
  }
  const auto id = (static_cast<unsigned>(data[0]) << 8) | static_cast<unsigned>(data[1]);
  if (id != 0x0001) {
    char text[8];
    std::snprintf(text, sizeof(text), "0x%04x", id);
    throw CdrError("CDR " + type_ + ": encapsulation " + text +
                   (id == 0x0000 ? " (big-endian CDR) is not supported"
                                 : " is not supported (expected 0x0001, little-endian XCDR1)"));
  }
  position_ = kEncapsulationSize;
}

void CdrReader::Align(size_t alignment) {
  const size_t misalignment = (position_ - kEncapsulationSize) % alignment;
  if (misalignment == 0) return;
  const size_t padding = alignment - misalignment;
  // Padding past the end is reported by the read that follows (Need).
  position_ = padding > remaining() ? data_.size() + 1 : position_ + padding;
}

void CdrReader::Need(uint64_t bytes, std::string_view field) const {
  if (position_ > data_.size()) {
    Fail(field, "alignment padding runs past the end of the " + std::to_string(data_.size()) +
                    "-byte buffer");
  }
  if (bytes > remaining()) {
    Fail(field,
         std::to_string(bytes) + " bytes needed, only " + std::to_string(remaining()) + " left");
  }
}

void CdrReader::Fail(std::string_view field, const std::string& problem) const {
  throw CdrError("CDR " + type_ + ": field '" + std::string(field) + "' at offset " +
                 std::to_string(std::min(position_, data_.size())) + ": " + problem);
}

bool CdrReader::Bool(std::string_view field) {
  const uint8_t value = Read<uint8_t>(field);
  if (value > 1) Fail(field, "bool byte " + std::to_string(value) + " is neither 0 nor 1");
  return value == 1;
}

std::string CdrReader::String(std::string_view field) {
  const uint32_t length = Read<uint32_t>(field);
  if (length == 0) Fail(field, "string length 0 (must count the terminating NUL)");
  Need(length, field);
  const char* chars = reinterpret_cast<const char*>(data_.data() + position_);
  if (chars[length - 1] != '\0') Fail(field, "string does not end in NUL");
  position_ += length;
  return std::string(chars, length - 1);
}

}  // namespace probeless::log
