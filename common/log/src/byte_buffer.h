// A growable byte buffer that, unlike std::vector, does not zero the bytes it grows by (appending
// megabyte-sized messages must cost one memcpy, not a memset and a memcpy).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>

namespace probeless::log::internal {

class ByteBuffer {
 public:
  // Grows the size by `bytes` (uninitialised) and returns a pointer to the new bytes.
  uint8_t* Extend(size_t bytes) {
    if (size_ + bytes > capacity_) Reserve(std::max(size_ + bytes, capacity_ * 2));
    uint8_t* at = data_.get() + size_;
    size_ += bytes;
    return at;
  }
  void Append(const void* bytes, size_t size) {
    if (size > 0) std::memcpy(Extend(size), bytes, size);
  }
  void Reserve(size_t capacity) {
    if (capacity <= capacity_) return;
    std::unique_ptr<uint8_t[]> grown(new uint8_t[capacity]);
    if (size_ > 0) std::memcpy(grown.get(), data_.get(), size_);
    data_ = std::move(grown);
    capacity_ = capacity;
  }
  // Sets the size (bytes beyond the old size are uninitialised).
  void Resize(size_t size) {
    Reserve(size);
    size_ = size;
  }
  void Clear() { size_ = 0; }
  // Frees the memory.
  void Release() {
    data_.reset();
    size_ = 0;
    capacity_ = 0;
  }

  uint8_t* data() { return data_.get(); }
  const uint8_t* data() const { return data_.get(); }
  size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  std::span<const uint8_t> span() const { return {data_.get(), size_}; }

 private:
  std::unique_ptr<uint8_t[]> data_;
  size_t size_ = 0;
  size_t capacity_ = 0;
};

}  // namespace probeless::log::internal
