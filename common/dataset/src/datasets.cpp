#include "probeless/dataset/datasets.h"

#include <algorithm>
#include <filesystem>
#include <system_error>

#include "internal.h"
#include "probeless/dataset/yaleb.h"

namespace probeless::dataset {

namespace fs = std::filesystem;

namespace {

constexpr std::string_view kLookedFor =
    "rgb.txt + depth.txt (tum), frame-XXXXXX.color.jpg|png (7scenes), "
    "yaleBxx_P00A±aaaE±ee.pgm files or yaleBxx/ folders of them (yaleb), "
    "png/jpg/jpeg/pgm/ppm/bmp files (images)";

bool IsVideoFileName(const std::string& name) {
  static const char* const kExtensions[] = {"avi", "mp4", "mkv",  "mov", "webm",
                                            "m4v", "mpg", "mpeg", "wmv"};
  const std::string ext = internal::LowerExtension(name);
  return std::any_of(std::begin(kExtensions), std::end(kExtensions),
                     [&](const char* e) { return ext == e; });
}

bool HasYaleBImages(const std::string& dir) {
  const std::vector<std::string> files = internal::ListFiles(dir);
  return std::any_of(files.begin(), files.end(),
                     [](const std::string& name) { return ParseYaleBName(name).has_value(); });
}

bool IsYaleBSubjectFolder(const std::string& name) {
  return name.size() == 7 && name.starts_with("yaleB") && name[5] >= '0' && name[5] <= '9' &&
         name[6] >= '0' && name[6] <= '9';
}

std::string DetectFolderKind(const std::string& path) {
  const std::vector<std::string> files = internal::ListFiles(path);
  auto has = [&](const std::string& name) {
    return std::binary_search(files.begin(), files.end(), name);
  };
  if (has("rgb.txt") && has("depth.txt")) return "tum";
  const bool seven_scenes = std::any_of(files.begin(), files.end(), [](const std::string& name) {
    return name.starts_with("frame-") &&
           (name.ends_with(".color.jpg") || name.ends_with(".color.png"));
  });
  if (seven_scenes) return "7scenes";
  if (HasYaleBImages(path)) return "yaleb";
  for (const std::string& folder : internal::ListFolders(path)) {
    if (IsYaleBSubjectFolder(folder) && HasYaleBImages(internal::JoinPath(path, folder))) {
      return "yaleb";
    }
  }
  if (std::any_of(files.begin(), files.end(), internal::IsImageFileName)) return "images";
  throw DatasetError("no dataset found in folder '" + path + "': looked for " +
                     std::string(kLookedFor));
}

bool IsKnownKind(const std::string& kind) {
  const std::vector<std::string>& kinds = DatasetKinds();
  return kind == "mcap" || std::find(kinds.begin(), kinds.end(), kind) != kinds.end();
}

}  // namespace

const std::vector<std::string>& DatasetKinds() {
  static const std::vector<std::string> kKinds = {"tum", "7scenes", "yaleb", "images", "video"};
  return kKinds;
}

std::string DetectDatasetKind(const std::string& path) {
  std::error_code error;
  const fs::file_status status = fs::status(path, error);
  if (path.empty() || error || !fs::exists(status)) {
    throw DatasetError("dataset path '" + path + "' does not exist");
  }
  if (fs::is_directory(status)) return DetectFolderKind(path);
  if (internal::LowerExtension(path) == "mcap") return "mcap";
  if (IsVideoFileName(path)) return "video";
  throw DatasetError("no dataset kind for file '" + path +
                     "': expected a folder (tum, 7scenes, yaleb, images), a video file "
                     "(avi, mp4, mkv, mov, webm, m4v, mpg, mpeg, wmv) or an .mcap log");
}

std::unique_ptr<Source> OpenDataset(const std::string& spec, const DatasetOptions& options) {
  std::string kind;
  std::string path = spec;
  const size_t colon = spec.find(':');
  if (colon != std::string::npos && colon > 0) {
    const std::string prefix = spec.substr(0, colon);
    const bool kind_like = std::all_of(prefix.begin(), prefix.end(), [](char c) {
      return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9');
    });
    std::error_code error;
    if (kind_like && IsKnownKind(prefix)) {
      kind = prefix;
      path = spec.substr(colon + 1);
    } else if (kind_like && !fs::exists(spec, error)) {
      throw DatasetError("unknown dataset kind '" + prefix + "' in '" + spec +
                         "' (expected 7scenes, tum, yaleb, images or video)");
    }
  }
  if (path.empty()) throw DatasetError("dataset spec '" + spec + "' names no path");
  std::error_code error;
  const fs::file_status status = fs::status(path, error);
  if (error || !fs::exists(status)) {
    throw DatasetError("dataset path '" + path + "' does not exist");
  }
  if (kind.empty()) kind = DetectDatasetKind(path);
  if (kind == "mcap") {
    throw DatasetError("'" + path +
                       "' is an MCAP log: open it with the MCAP source, not as a dataset folder");
  }
  internal::CheckOptions(options, kind);
  if (kind == "video") {
    if (fs::is_directory(status)) {
      throw DatasetError("video path '" + path + "' is a folder: expected a video file");
    }
    return internal::OpenVideo(path, options);
  }
  if (!fs::is_directory(status)) {
    throw DatasetError(kind + " dataset path '" + path + "' is not a folder");
  }
  if (kind == "tum") return internal::OpenTum(path, options);
  if (kind == "7scenes") return internal::OpenSevenScenes(path, options);
  if (kind == "yaleb") return internal::OpenYaleB(path, options);
  return internal::OpenImages(path, options);
}

}  // namespace probeless::dataset
