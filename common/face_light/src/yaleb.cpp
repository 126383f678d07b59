// Extended Yale B file names and image loading (OpenCV stays in this file).
#include "probeless/face_light/yaleb.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <set>

#include "probeless/sh/sh.h"

namespace probeless::face_light {
namespace {

// Parses exactly `digits` decimal digits at text[pos].
std::optional<int> Digits(std::string_view text, size_t pos, size_t digits) {
  if (pos + digits > text.size()) return std::nullopt;
  int value = 0;
  for (size_t i = 0; i < digits; ++i) {
    const char c = text[pos + i];
    if (c < '0' || c > '9') return std::nullopt;
    value = value * 10 + (c - '0');
  }
  return value;
}

std::string SubjectFolder(int subject) {
  char name[16];
  std::snprintf(name, sizeof name, "yaleB%02d", subject);
  return name;
}

}  // namespace

std::vector<int> ListYaleBSubjects(const std::string& dir) {
  std::error_code error;
  if (!std::filesystem::is_directory(dir, error)) {
    throw FaceLightError(dir + ": not a directory (expected the Yale B folder with yaleBxx/)");
  }
  std::vector<int> subjects;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    if (!entry.is_directory() || name.size() != 7 || name.substr(0, 5) != "yaleB") continue;
    if (const auto subject = Digits(name, 5, 2)) subjects.push_back(*subject);
  }
  std::sort(subjects.begin(), subjects.end());
  return subjects;
}

std::vector<int> ParseSubjectList(std::string_view text) {
  std::set<int> subjects;
  const auto fail = [&]() {
    throw FaceLightError("bad subject list '" + std::string(text) +
                         "' (expected e.g. 1-28 or 1,3,5-7 with numbers 1..99)");
  };
  const auto number = [&](std::string_view word) {
    int value = 0;
    const auto [end, error] = std::from_chars(word.data(), word.data() + word.size(), value);
    if (word.empty() || error != std::errc() || end != word.data() + word.size() || value < 1 ||
        value > 99) {
      fail();
    }
    return value;
  };
  if (text.empty()) fail();
  size_t start = 0;
  while (start <= text.size()) {
    const size_t comma = std::min(text.find(',', start), text.size());
    const std::string_view item = text.substr(start, comma - start);
    const size_t dash = item.find('-');
    if (dash == std::string_view::npos) {
      subjects.insert(number(item));
    } else {
      const int first = number(item.substr(0, dash)), last = number(item.substr(dash + 1));
      if (last < first) fail();
      for (int s = first; s <= last; ++s) subjects.insert(s);
    }
    start = comma + 1;
  }
  return {subjects.begin(), subjects.end()};
}

std::vector<YaleBImage> LoadYaleBSubject(const std::string& dir, int subject) {
  const std::filesystem::path folder = std::filesystem::path(dir) / SubjectFolder(subject);
  std::error_code error;
  if (!std::filesystem::is_directory(folder, error)) {
    throw FaceLightError(folder.string() + ": no such subject folder");
  }
  std::vector<std::filesystem::path> files;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    const auto name = ParseYaleBName(entry.path().filename().string());
    if (name && name->subject == subject) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) throw FaceLightError(folder.string() + ": no light images");
  std::vector<YaleBImage> images;
  for (const auto& path : files) {
    const cv::Mat mat = cv::imread(path.string(), cv::IMREAD_GRAYSCALE);
    if (mat.empty()) throw FaceLightError(path.string() + ": cannot decode image");
    if (mat.cols != kCropWidth || mat.rows != kCropHeight) {
      throw FaceLightError(path.string() + ": image is " + std::to_string(mat.cols) + "x" +
                           std::to_string(mat.rows) + ", expected the 168x192 crop");
    }
    YaleBImage image;
    image.name = *ParseYaleBName(path.filename().string());
    image.path = path.string();
    image.width = mat.cols;
    image.height = mat.rows;
    image.pixels.resize(static_cast<size_t>(mat.cols) * mat.rows);
    for (int y = 0; y < mat.rows; ++y) {
      std::copy(mat.ptr<uint8_t>(y), mat.ptr<uint8_t>(y) + mat.cols,
                image.pixels.begin() + static_cast<size_t>(y) * mat.cols);
    }
    images.push_back(std::move(image));
  }
  return images;
}

}  // namespace probeless::face_light
