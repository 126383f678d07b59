// zstd and LZ4-frame compression of chunk records (keeps zstd.h and lz4frame.h out of headers).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "probeless/log/mcap.h"

namespace probeless::log::internal {

// Empty if `level` is valid for `compression` (0 = fast default; zstd -5..22, lz4 0..12), else
// a one-line description of the problem.
std::string CheckCompressionLevel(Compression compression, int level);

// Compresses with reusable contexts. One thread at a time.
class Compressor {
 public:
  // `level` must pass CheckCompressionLevel. Throws LogError if a context cannot be created.
  Compressor(Compression compression, int level);
  ~Compressor();
  Compressor(const Compressor&) = delete;
  Compressor& operator=(const Compressor&) = delete;

  // Replaces `out` with the compressed form of `in` (one zstd or LZ4 frame). Must not be called
  // for Compression::kNone. Throws LogError (prefix "<what>: ") if the library fails.
  void Compress(std::span<const uint8_t> in, std::vector<uint8_t>& out);

 private:
  Compression compression_;
  int level_;
  void* zstd_ = nullptr;  // ZSTD_CCtx*
  void* lz4_ = nullptr;   // LZ4F_cctx*
};

// Decompresses with reusable contexts. One thread at a time.
class Decompressor {
 public:
  Decompressor();
  ~Decompressor();
  Decompressor(const Decompressor&) = delete;
  Decompressor& operator=(const Decompressor&) = delete;

  // Decompresses exactly one frame `in` into `out`, whose size is the expected uncompressed size.
  // Returns an empty string on success, else a one-line description of the problem (corrupt
  // frame, size mismatch, trailing bytes). Never writes past `out`.
  std::string Decompress(Compression compression, std::span<const uint8_t> in,
                         std::span<uint8_t> out);

 private:
  void* zstd_ = nullptr;  // ZSTD_DCtx*
  void* lz4_ = nullptr;   // LZ4F_dctx*
};

}  // namespace probeless::log::internal
