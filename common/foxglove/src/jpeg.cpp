#include "probeless/foxglove/jpeg.h"

#include <csetjmp>
#include <cstdio>
#include <cstdlib>
#include <string>

// jpeglib.h needs size_t and FILE declared first.
#include <jpeglib.h>

#include "probeless/foxglove/protocol.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/image.h"

namespace probeless::foxglove {
namespace {

struct ErrorManager {
  jpeg_error_mgr base;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
};

void OnError(j_common_ptr info) {
  auto* e = reinterpret_cast<ErrorManager*>(info->err);
  (*info->err->format_message)(info, e->message);
  std::longjmp(e->jump, 1);
}

}  // namespace

std::vector<std::byte> EncodeJpeg(std::span<const std::byte> image_message, int quality) {
  if (quality < 1 || quality > 100) {
    throw FoxgloveError("JPEG quality " + std::to_string(quality) + " out of range (1..100)");
  }
  msgs::ReadView<msgs::Image> image;
  try {
    image = msgs::ReadMessage<msgs::Image>(image_message);
    image->Validate(image.payload.size());
  } catch (const msgs::MessageError& e) {
    throw FoxgloveError(std::string("JPEG: ") + e.what());
  }
  J_COLOR_SPACE space;
  int components;
  switch (image->encoding) {
    case msgs::Encoding::kRgb8:
      space = JCS_RGB;
      components = 3;
      break;
    case msgs::Encoding::kBgr8:
      space = JCS_EXT_BGR;
      components = 3;
      break;
    case msgs::Encoding::kMono8:
      space = JCS_GRAYSCALE;
      components = 1;
      break;
    default:
      throw FoxgloveError("JPEG: image encoding " +
                          std::string(msgs::EncodingName(image->encoding)) +
                          " cannot be compressed (expected rgb8, bgr8 or mono8)");
  }
  jpeg_compress_struct info{};
  ErrorManager error{};
  info.err = jpeg_std_error(&error.base);
  error.base.error_exit = OnError;
  unsigned char* buffer = nullptr;
  unsigned long size = 0;
  // Nothing with a destructor lives between setjmp and a possible longjmp.
  if (setjmp(error.jump) != 0) {
    jpeg_destroy_compress(&info);
    std::free(buffer);
    throw FoxgloveError(std::string("JPEG: ") + error.message);
  }
  jpeg_create_compress(&info);
  jpeg_mem_dest(&info, &buffer, &size);
  info.image_width = image->width;
  info.image_height = image->height;
  info.input_components = components;
  info.in_color_space = space;
  jpeg_set_defaults(&info);
  jpeg_set_quality(&info, quality, TRUE);
  jpeg_start_compress(&info, TRUE);
  const auto* pixels = reinterpret_cast<const unsigned char*>(image.payload.data());
  while (info.next_scanline < info.image_height) {
    JSAMPROW row = const_cast<unsigned char*>(pixels + size_t{info.next_scanline} * image->step);
    jpeg_write_scanlines(&info, &row, 1);
  }
  jpeg_finish_compress(&info);
  jpeg_destroy_compress(&info);
  std::vector<std::byte> out(reinterpret_cast<const std::byte*>(buffer),
                             reinterpret_cast<const std::byte*>(buffer) + size);
  std::free(buffer);
  return out;
}

void EncodeCompressedImageCdr(std::span<const std::byte> image_message, int quality,
                              log::CdrWriter& out) {
  const std::vector<std::byte> jpeg = EncodeJpeg(image_message, quality);
  const auto image = msgs::ReadMessage<msgs::Image>(image_message);
  out.Reset();
  log::EncodeCompressedImage(image->header, "jpeg", jpeg, out);
}

}  // namespace probeless::foxglove
