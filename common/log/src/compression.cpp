#include "compression.h"

#include <lz4frame.h>
#include <zstd.h>
#include <zstd_errors.h>

#include <string>

namespace probeless::log::internal {
namespace {

ZSTD_CCtx* Zc(void* p) { return static_cast<ZSTD_CCtx*>(p); }
ZSTD_DCtx* Zd(void* p) { return static_cast<ZSTD_DCtx*>(p); }
LZ4F_cctx* Lc(void* p) { return static_cast<LZ4F_cctx*>(p); }
LZ4F_dctx* Ld(void* p) { return static_cast<LZ4F_dctx*>(p); }

}  // namespace

std::string CheckCompressionLevel(Compression compression, int level) {
  if (compression == Compression::kZstd && (level < -5 || level > ZSTD_maxCLevel())) {
    return "zstd compression level " + std::to_string(level) + " out of range -5.." +
           std::to_string(ZSTD_maxCLevel());
  }
  if (compression == Compression::kLz4 && (level < 0 || level > LZ4F_compressionLevel_max())) {
    return "lz4 compression level " + std::to_string(level) + " out of range 0.." +
           std::to_string(LZ4F_compressionLevel_max());
  }
  return "";
}

Compressor::Compressor(Compression compression, int level)
    : compression_(compression), level_(level) {
  switch (compression) {
    case Compression::kNone:
      break;
    case Compression::kZstd: {
      ZSTD_CCtx* context = ZSTD_createCCtx();
      if (context == nullptr) throw LogError("zstd: cannot create a compression context");
      ZSTD_CCtx_setParameter(context, ZSTD_c_compressionLevel, level == 0 ? 1 : level);
      zstd_ = context;
      break;
    }
    case Compression::kLz4: {
      LZ4F_cctx* context = nullptr;
      if (LZ4F_isError(LZ4F_createCompressionContext(&context, LZ4F_VERSION))) {
        throw LogError("lz4: cannot create a compression context");
      }
      lz4_ = context;
      break;
    }
  }
}

Compressor::~Compressor() {
  if (zstd_ != nullptr) ZSTD_freeCCtx(Zc(zstd_));
  if (lz4_ != nullptr) LZ4F_freeCompressionContext(Lc(lz4_));
}

void Compressor::Compress(std::span<const uint8_t> in, std::vector<uint8_t>& out) {
  if (compression_ == Compression::kZstd) {
    out.resize(ZSTD_compressBound(in.size()));
    const size_t written = ZSTD_compress2(Zc(zstd_), out.data(), out.size(), in.data(), in.size());
    if (ZSTD_isError(written)) {
      throw LogError(std::string("zstd compression failed: ") + ZSTD_getErrorName(written));
    }
    out.resize(written);
    return;
  }
  if (compression_ == Compression::kLz4) {
    LZ4F_preferences_t preferences{};
    preferences.frameInfo.blockSizeID = LZ4F_max4MB;
    preferences.frameInfo.blockMode = LZ4F_blockLinked;
    preferences.frameInfo.contentSize = in.size();
    preferences.compressionLevel = level_;
    preferences.autoFlush = 1;
    out.resize(LZ4F_compressFrameBound(in.size(), &preferences));
    size_t at = LZ4F_compressBegin(Lc(lz4_), out.data(), out.size(), &preferences);
    if (!LZ4F_isError(at)) {
      const size_t body = LZ4F_compressUpdate(Lc(lz4_), out.data() + at, out.size() - at, in.data(),
                                              in.size(), nullptr);
      at = LZ4F_isError(body) ? body : at + body;
    }
    if (!LZ4F_isError(at)) {
      const size_t end = LZ4F_compressEnd(Lc(lz4_), out.data() + at, out.size() - at, nullptr);
      at = LZ4F_isError(end) ? end : at + end;
    }
    if (LZ4F_isError(at)) {
      throw LogError(std::string("lz4 compression failed: ") + LZ4F_getErrorName(at));
    }
    out.resize(at);
    return;
  }
  throw LogError("Compressor::Compress called for uncompressed chunks");
}

Decompressor::Decompressor() = default;

Decompressor::~Decompressor() {
  if (zstd_ != nullptr) ZSTD_freeDCtx(Zd(zstd_));
  if (lz4_ != nullptr) LZ4F_freeDecompressionContext(Ld(lz4_));
}

std::string Decompressor::Decompress(Compression compression, std::span<const uint8_t> in,
                                     std::span<uint8_t> out) {
  uint8_t dummy = 0;  // libraries want a valid pointer even for empty buffers
  uint8_t* const out_data = out.empty() ? &dummy : out.data();
  const uint8_t* const in_data = in.empty() ? &dummy : in.data();
  switch (compression) {
    case Compression::kNone:
      return "no decompression needed";
    case Compression::kZstd: {
      if (zstd_ == nullptr) {
        zstd_ = ZSTD_createDCtx();
        if (zstd_ == nullptr) return "zstd: cannot create a decompression context";
      }
      const size_t size = ZSTD_decompressDCtx(Zd(zstd_), out_data, out.size(), in_data, in.size());
      if (ZSTD_isError(size)) {
        if (ZSTD_getErrorCode(size) == ZSTD_error_dstSize_tooSmall) {
          return "zstd data decompress to more than the " + std::to_string(out.size()) +
                 " bytes the chunk declares";
        }
        return std::string("zstd decompression failed: ") + ZSTD_getErrorName(size);
      }
      if (size != out.size()) {
        return "zstd data decompress to " + std::to_string(size) + " bytes, the chunk declares " +
               std::to_string(out.size());
      }
      return "";
    }
    case Compression::kLz4: {
      if (lz4_ == nullptr) {
        LZ4F_dctx* context = nullptr;
        if (LZ4F_isError(LZ4F_createDecompressionContext(&context, LZ4F_VERSION))) {
          return "lz4: cannot create a decompression context";
        }
        lz4_ = context;
      }
      LZ4F_resetDecompressionContext(Ld(lz4_));
      size_t in_position = 0;
      size_t out_position = 0;
      LZ4F_decompressOptions_t options{};
      while (true) {
        size_t out_size = out.size() - out_position;
        size_t in_size = in.size() - in_position;
        const size_t hint = LZ4F_decompress(Ld(lz4_), out_data + out_position, &out_size,
                                            in_data + in_position, &in_size, &options);
        if (LZ4F_isError(hint)) {
          return std::string("lz4 decompression failed: ") + LZ4F_getErrorName(hint);
        }
        in_position += in_size;
        out_position += out_size;
        if (hint == 0) break;  // frame complete
        if (in_size == 0 && out_size == 0) {
          if (in_position == in.size()) return "lz4 frame ends early";
          return "lz4 data decompress to more than the " + std::to_string(out.size()) +
                 " bytes the chunk declares";
        }
      }
      if (in_position != in.size()) {
        return std::to_string(in.size() - in_position) + " bytes follow the lz4 frame";
      }
      if (out_position != out.size()) {
        return "lz4 data decompress to " + std::to_string(out_position) +
               " bytes, the chunk declares " + std::to_string(out.size());
      }
      return "";
    }
  }
  return "unknown compression";
}

}  // namespace probeless::log::internal
