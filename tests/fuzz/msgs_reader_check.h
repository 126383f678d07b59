// What every node does with a received bus sample, on arbitrary bytes: view it as the message type
// `kind` picks (msgs::ReadMessage), validate it and read its strings and every payload plane
// through the accessors the nodes use. Only msgs::MessageError may escape; an accepted message
// must keep the accessors' contracts (spans inside the sample). Shared by msgs_reader_fuzz
// (libFuzzer) and msgs_reader_mutation_test (fixed-seed mutations in every test build,
// sanitizers included, since clang 14 cannot compile these headers for libFuzzer).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <new>
#include <span>
#include <string>

#include "probeless/msgs/msgs.h"

namespace probeless::fuzz {

inline constexpr int kMessageKinds = 9;

// The bytes as a bus sample: exactly size bytes (so ASan sees a read past the end), 64-byte
// aligned like a bus slot.
class AlignedSample {
 public:
  AlignedSample(const uint8_t* data, size_t size)
      : size_(size),
        bytes_(
            static_cast<std::byte*>(::operator new (size == 0 ? 1 : size, std::align_val_t{64}))) {
    for (size_t i = 0; i < size; ++i) bytes_[i] = static_cast<std::byte>(data[i]);
  }
  ~AlignedSample() { ::operator delete (bytes_, std::align_val_t{64}); }
  AlignedSample(const AlignedSample&) = delete;
  AlignedSample& operator=(const AlignedSample&) = delete;
  std::span<const std::byte> bytes() const { return {bytes_, size_}; }
  std::span<std::byte> mutable_bytes() { return {bytes_, size_}; }

 private:
  size_t size_;
  std::byte* bytes_;
};

namespace msgs_check_internal {

inline void Demand(bool condition) {
  if (!condition) std::abort();  // libFuzzer keeps the input; gtest reports the death
}

// A span the accessors returned lies inside the sample; its first and last element are read.
template <class T>
uint64_t Touch(std::span<const T> span, std::span<const std::byte> sample) {
  if (span.empty()) return 0;
  const auto* begin = reinterpret_cast<const std::byte*>(span.data());
  const auto* end = reinterpret_cast<const std::byte*>(span.data() + span.size());
  Demand(begin >= sample.data() && end <= sample.data() + sample.size());
  T first = span.front(), last = span.back();
  uint64_t bits = 0;
  static_assert(sizeof(T) <= sizeof(bits));
  std::memcpy(&bits, &first, sizeof(T));
  uint64_t more = 0;
  std::memcpy(&more, &last, sizeof(T));
  return bits ^ more;
}

inline uint64_t Text(std::string_view text) {
  uint64_t h = 0;
  for (char c : text) h = h * 31 + static_cast<unsigned char>(c);
  return h;
}

}  // namespace msgs_check_internal

// Runs the readers of message kind `kind % kMessageKinds` over `sample`; returns a value derived
// from what was read (so the reads are not optimised away). Throws msgs::MessageError only.
inline uint64_t ReadAsMessage(uint8_t kind, std::span<const std::byte> sample) {
  using namespace probeless::msgs;
  using msgs_check_internal::Demand;
  using msgs_check_internal::Text;
  using msgs_check_internal::Touch;
  uint64_t seen = 0;
  switch (kind % kMessageKinds) {
    case 0: {
      const auto m = ReadMessage<Image>(sample);
      seen ^= Text(m->header.FrameId()) ^ Text(m->Describe());
      m->Validate(m.payload.size());
      Demand(m->PayloadBytes() <= m.payload.size());
      switch (BytesPerChannel(m->encoding)) {
        case 1:
          seen ^= Touch(ImageChannels<uint8_t>(*m, m.payload), sample);
          if (m->height > 0) seen ^= Touch(ImageRow<uint8_t>(*m, m.payload, m->height - 1), sample);
          break;
        case 2:
          seen ^= Touch(ImageChannels<uint16_t>(*m, m.payload), sample);
          if (m->height > 0) {
            seen ^= Touch(ImageRow<uint16_t>(*m, m.payload, m->height - 1), sample);
          }
          break;
        default:
          seen ^= Touch(ImageChannels<float>(*m, m.payload), sample);
          if (m->height > 0) seen ^= Touch(ImageRow<float>(*m, m.payload, m->height - 1), sample);
      }
      break;
    }
    case 1: {
      const auto m = ReadMessage<CameraInfo>(sample);
      seen ^= Text(m->header.FrameId());
      m->Validate();
      break;
    }
    case 2: {
      const auto m = ReadMessage<GeometryBuffer>(sample);
      seen ^= Text(m->header.FrameId());
      m->Validate(m.payload.size());
      seen ^= Touch(DepthPlane(*m, m.payload), sample);
      seen ^= Touch(NormalsPlane(*m, m.payload), sample);
      seen ^= Touch(ColourPlane(*m, m.payload), sample);
      break;
    }
    case 3: {
      const auto m = ReadMessage<TransferBuffer>(sample);
      seen ^= Touch(TransferCoefficients(*m, m.payload), sample);
      if (m->width > 0 && m->height > 0) {
        seen ^= Touch(PixelTransfer(*m, m.payload, m->width - 1, m->height - 1), sample);
      }
      break;
    }
    case 4: {
      const auto m = ReadMessage<AuxiliaryViews>(sample);
      m->Validate(m.payload.size());
      for (uint32_t v = 0; v < m->view_count; ++v) {
        seen ^= Touch(AuxiliaryDepth(*m, m.payload, v), sample);
        seen ^= Text(AuxiliaryViewRoleName(m->views[v].role));
      }
      break;
    }
    case 5: {
      const auto m = ReadMessage<ShLight>(sample);
      seen ^= Text(m->header.FrameId());
      m->Validate();
      break;
    }
    case 6: {
      const auto m = ReadMessage<FaceObservation>(sample);
      seen ^= Text(m->header.FrameId());
      m->Validate();
      break;
    }
    case 7: {
      const auto m = ReadMessage<TrackingStatus>(sample);
      seen ^= Text(m->header.FrameId());
      m->Validate();
      break;
    }
    default: {
      const auto m = ReadMessage<Ack>(sample);
      seen ^= Text(m->Topic()) ^ Text(m->header.FrameId());
      break;
    }
  }
  return seen;
}

}  // namespace probeless::fuzz
