#include "crc32.h"

#include <array>
#include <cstring>

namespace probeless::log::internal {
namespace {

constexpr uint32_t kPolynomial = 0xEDB88320u;

// kTables[0] is the classic byte table; kTables[k][b] is the CRC of byte b followed by k zero
// bytes, which lets the loop fold 8 input bytes per step.
constexpr std::array<std::array<uint32_t, 256>, 8> MakeTables() {
  std::array<std::array<uint32_t, 256>, 8> tables{};
  for (uint32_t b = 0; b < 256; ++b) {
    uint32_t crc = b;
    for (int bit = 0; bit < 8; ++bit) crc = (crc >> 1) ^ ((crc & 1u) ? kPolynomial : 0u);
    tables[0][b] = crc;
  }
  for (uint32_t b = 0; b < 256; ++b) {
    for (int k = 1; k < 8; ++k) {
      const uint32_t previous = tables[k - 1][b];
      tables[k][b] = (previous >> 8) ^ tables[0][previous & 0xFFu];
    }
  }
  return tables;
}

constexpr auto kTables = MakeTables();

}  // namespace

uint32_t Crc32Update(uint32_t crc, const void* data, size_t size) {
  const auto* p = static_cast<const uint8_t*>(data);
  crc = ~crc;
  while (size >= 8) {
    uint32_t low;
    uint32_t high;
    std::memcpy(&low, p, 4);
    std::memcpy(&high, p + 4, 4);
    low ^= crc;  // little-endian host (static_assert in byte_io.h)
    crc = kTables[7][low & 0xFFu] ^ kTables[6][(low >> 8) & 0xFFu] ^
          kTables[5][(low >> 16) & 0xFFu] ^ kTables[4][low >> 24] ^ kTables[3][high & 0xFFu] ^
          kTables[2][(high >> 8) & 0xFFu] ^ kTables[1][(high >> 16) & 0xFFu] ^
          kTables[0][high >> 24];
    p += 8;
    size -= 8;
  }
  while (size-- > 0) crc = (crc >> 8) ^ kTables[0][(crc ^ *p++) & 0xFFu];
  return ~crc;
}

namespace {

// CRC arithmetic is linear over GF(2): appending one zero bit to the message maps the (finalised)
// CRC value v to a 32x32 bit matrix times v. A matrix is stored as its 32 columns; column i is
// the image of bit i.
using Matrix = std::array<uint32_t, 32>;

uint32_t Apply(const Matrix& matrix, uint32_t vector) {
  uint32_t result = 0;
  for (int i = 0; vector != 0; ++i, vector >>= 1) {
    if (vector & 1u) result ^= matrix[i];
  }
  return result;
}

Matrix Square(const Matrix& matrix) {
  Matrix result{};
  for (int i = 0; i < 32; ++i) result[i] = Apply(matrix, matrix[i]);
  return result;
}

}  // namespace

uint32_t Crc32Combine(uint32_t crc_a, uint32_t crc_b, uint64_t size_b) {
  if (size_b == 0) return crc_a;
  // One zero bit: shift right, folding the polynomial in when bit 0 falls out.
  Matrix power{};
  power[0] = kPolynomial;
  for (int i = 1; i < 32; ++i) power[i] = uint32_t{1} << (i - 1);
  // Square up to one zero byte (8 bits), then walk the bits of size_b: power = 2^k bytes.
  power = Square(Square(Square(power)));
  uint32_t shifted = crc_a;
  while (true) {
    if (size_b & 1u) shifted = Apply(power, shifted);
    size_b >>= 1;
    if (size_b == 0) break;
    power = Square(power);
  }
  return shifted ^ crc_b;
}

}  // namespace probeless::log::internal
