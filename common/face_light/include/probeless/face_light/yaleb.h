// Extended Yale Face Database B (cropped) access for training and evaluation: file names, light
// directions and images. Files "yaleBxx_P00A±aaaE±ee.pgm" in sub-folders yaleBxx/ of a data-set
// folder; positive azimuth = light from the subject's right = image left, positive elevation =
// from above. Ambient images ("..._Ambient.pgm") and other files are ignored.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/dataset/yaleb.h"
#include "probeless/face_light/model.h"

namespace probeless::face_light {

// File names and light directions: the dataset library's parser (probeless/dataset/yaleb.h).
// YaleBLightDirection gives the unit direction towards the light in the light frame (model.h).
using dataset::ParseYaleBName;
using dataset::YaleBLightDirection;
using dataset::YaleBName;

// Subject numbers with a yaleBxx/ folder under `dir`, ascending. Throws FaceLightError if `dir`
// is not a directory.
std::vector<int> ListYaleBSubjects(const std::string& dir);

// "1-28", "1,3,5-7" -> ascending unique subject numbers. Throws FaceLightError on bad syntax or
// numbers outside 1..99.
std::vector<int> ParseSubjectList(std::string_view text);

// One light image: 8-bit gray, row-major, width * height bytes.
struct YaleBImage {
  YaleBName name;
  std::string path;
  int width = 0;
  int height = 0;
  std::vector<uint8_t> pixels;
};

// The light images of one subject (ambient excluded), sorted by file name. Throws FaceLightError
// if the folder is missing, holds no light image, or an image cannot be decoded or is not
// 168 x 192.
std::vector<YaleBImage> LoadYaleBSubject(const std::string& dir, int subject);

}  // namespace probeless::face_light
