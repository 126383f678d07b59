// CRC-32 (IEEE 802.3, reflected polynomial 0xEDB88320, initial value and final xor 0xFFFFFFFF:
// the zlib/PNG/MCAP checksum), slicing-by-8.
#pragma once

#include <cstddef>
#include <cstdint>

namespace probeless::log::internal {

// Continues a CRC: Crc32Update(Crc32Update(0, a), b) == CRC of a followed by b. Start from 0.
uint32_t Crc32Update(uint32_t crc, const void* data, size_t size);

inline uint32_t Crc32(const void* data, size_t size) { return Crc32Update(0, data, size); }

// The CRC of A followed by B from crc_a = CRC(A), crc_b = CRC(B) and B's length, in O(log size_b)
// without touching the bytes (lets the writer reuse a chunk's CRC for the data section CRC).
uint32_t Crc32Combine(uint32_t crc_a, uint32_t crc_b, uint64_t size_b);

}  // namespace probeless::log::internal
