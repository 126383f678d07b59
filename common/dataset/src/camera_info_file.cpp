#include "camera_info_file.h"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <numbers>
#include <opencv2/core.hpp>
#include <string_view>

#include "internal.h"
#include "text_io.h"

namespace probeless::dataset::internal {

namespace {

// Sets model and coefficients from `count` coefficients (0, 4, 5 or 8).
void SetDistortion(Intrinsics& intrinsics, std::vector<double> coefficients,
                   const std::string& path) {
  switch (coefficients.size()) {
    case 0:
      intrinsics.model = msgs::DistortionModel::kNone;
      break;
    case 4:
      coefficients.push_back(0);  // k3 = 0
      [[fallthrough]];
    case 5:
      intrinsics.model = msgs::DistortionModel::kPlumbBob;
      break;
    case 8:
      intrinsics.model = msgs::DistortionModel::kRationalPolynomial;
      break;
    default:
      throw DatasetError("camera info '" + path + "' has " + std::to_string(coefficients.size()) +
                         " distortion coefficients: expected 0, 4, 5 (plumb_bob) or 8 "
                         "(rational_polynomial)");
  }
  intrinsics.distortion = std::move(coefficients);
}

void SetMatrix(Intrinsics& intrinsics, const std::vector<double>& k, const std::string& path) {
  if (k.size() != 9) {
    throw DatasetError("camera info '" + path + "': camera matrix has " + std::to_string(k.size()) +
                       " entries, expected 9 (3x3)");
  }
  intrinsics.fx = k[0];
  intrinsics.fy = k[4];
  intrinsics.cx = k[2];
  intrinsics.cy = k[5];
  if (!(intrinsics.fx > 0) || !(intrinsics.fy > 0)) {
    throw DatasetError("camera info '" + path +
                       "': camera matrix must have positive focal lengths fx, fy");
  }
}

uint32_t CheckedSize(double value, const std::string& path, std::string_view key) {
  if (!(value >= 0) || value > 1e6 || value != std::floor(value)) {
    throw DatasetError("camera info '" + path + "': " + std::string(key) +
                       " must be a non-negative whole number of pixels");
  }
  return static_cast<uint32_t>(value);
}

Intrinsics ReadRosYaml(const std::string& path, const std::string& text) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw DatasetError("camera info '" + path + "' is not valid YAML: " + e.what());
  }
  if (!root.IsMap()) {
    throw DatasetError("camera info '" + path +
                       "': expected a ROS camera_info YAML mapping (camera_matrix, ...)");
  }
  Intrinsics intrinsics;
  try {
    auto data_of = [&](std::string_view key) -> std::vector<double> {
      const YAML::Node node = root[std::string(key)];
      if (!node) return {};
      const YAML::Node data = node["data"];
      if (!data || !data.IsSequence()) {
        throw DatasetError("camera info '" + path + "': " + std::string(key) +
                           " needs a data list");
      }
      return data.as<std::vector<double>>();
    };
    if (!root["camera_matrix"]) {
      throw DatasetError("camera info '" + path +
                         "': missing camera_matrix (expected a ROS camera_info YAML file)");
    }
    SetMatrix(intrinsics, data_of("camera_matrix"), path);
    if (root["image_width"]) {
      intrinsics.width = CheckedSize(root["image_width"].as<double>(), path, "image_width");
    }
    if (root["image_height"]) {
      intrinsics.height = CheckedSize(root["image_height"].as<double>(), path, "image_height");
    }
    const std::string model =
        root["distortion_model"] ? root["distortion_model"].as<std::string>() : "plumb_bob";
    std::vector<double> coefficients = data_of("distortion_coefficients");
    if (model != "plumb_bob" && model != "rational_polynomial") {
      throw DatasetError("camera info '" + path + "': distortion_model '" + model +
                         "' is not supported (expected plumb_bob or rational_polynomial)");
    }
    SetDistortion(intrinsics, std::move(coefficients), path);
    if (model == "rational_polynomial" &&
        intrinsics.model != msgs::DistortionModel::kRationalPolynomial &&
        intrinsics.model != msgs::DistortionModel::kNone) {
      throw DatasetError("camera info '" + path +
                         "': rational_polynomial needs 8 distortion coefficients");
    }
  } catch (const YAML::Exception& e) {
    throw DatasetError("camera info '" + path + "': malformed entry: " + e.what());
  }
  return intrinsics;
}

Intrinsics ReadFileStorage(const std::string& path) {
  cv::FileStorage storage;
  try {
    storage.open(path, cv::FileStorage::READ);
  } catch (const cv::Exception& e) {
    throw DatasetError("camera info '" + path +
                       "' is not a readable OpenCV FileStorage YAML/XML file");
  }
  if (!storage.isOpened()) {
    throw DatasetError("camera info '" + path +
                       "' is not a readable OpenCV FileStorage YAML/XML file");
  }
  auto find = [&](std::initializer_list<const char*> keys) -> cv::FileNode {
    for (const char* key : keys) {
      cv::FileNode node = storage[key];
      if (!node.empty()) return node;
    }
    return {};
  };
  auto matrix_values = [&](const cv::FileNode& node, std::string_view what) {
    cv::Mat mat;
    try {
      node >> mat;
    } catch (const cv::Exception&) {
      mat.release();
    }
    if (mat.empty() && !node.empty()) {
      throw DatasetError("camera info '" + path + "': " + std::string(what) +
                         " is not an opencv-matrix");
    }
    std::vector<double> values;
    cv::Mat as_double;
    mat.convertTo(as_double, CV_64F);
    for (int r = 0; r < as_double.rows; ++r) {
      for (int c = 0; c < as_double.cols; ++c) values.push_back(as_double.at<double>(r, c));
    }
    return values;
  };
  Intrinsics intrinsics;
  const cv::FileNode k = find({"camera_matrix", "cameraMatrix", "K"});
  if (k.empty()) {
    throw DatasetError("camera info '" + path +
                       "': missing camera_matrix (or cameraMatrix, K) in OpenCV FileStorage file");
  }
  SetMatrix(intrinsics, matrix_values(k, "camera_matrix"), path);
  const cv::FileNode d =
      find({"distortion_coefficients", "distCoeffs", "dist_coeffs", "distortion", "D"});
  SetDistortion(intrinsics, d.empty() ? std::vector<double>() : matrix_values(d, "distortion"),
                path);
  const cv::FileNode w = find({"image_width", "width"});
  const cv::FileNode h = find({"image_height", "height"});
  if (!w.empty()) intrinsics.width = CheckedSize(static_cast<double>(w), path, "image_width");
  if (!h.empty()) intrinsics.height = CheckedSize(static_cast<double>(h), path, "image_height");
  return intrinsics;
}

}  // namespace

Intrinsics ReadCameraInfoFile(const std::string& path) {
  const std::string text = ReadTextFile(path, "camera info");
  size_t start = 0;
  while (start < text.size() && std::isspace(static_cast<unsigned char>(text[start]))) ++start;
  const std::string_view head = std::string_view(text).substr(start);
  if (head.starts_with("%YAML:1") || head.starts_with("<?xml") ||
      head.starts_with("<opencv_storage")) {
    return ReadFileStorage(path);
  }
  return ReadRosYaml(path, text);
}

Intrinsics GuessIntrinsics(uint32_t width, uint32_t height) {
  Intrinsics intrinsics;
  intrinsics.width = width;
  intrinsics.height = height;
  const double focal = width / (2 * std::tan(30.0 * std::numbers::pi / 180.0));
  intrinsics.fx = focal;
  intrinsics.fy = focal;
  intrinsics.cx = (width - 1) / 2.0;
  intrinsics.cy = (height - 1) / 2.0;
  return intrinsics;
}

Intrinsics ResolveIntrinsics(const DatasetOptions& options, const Intrinsics& fallback,
                             uint32_t width, uint32_t height) {
  Intrinsics intrinsics = fallback;
  if (!options.camera_info_path.empty()) {
    intrinsics = ReadCameraInfoFile(options.camera_info_path);
    if ((intrinsics.width != 0 && intrinsics.width != width) ||
        (intrinsics.height != 0 && intrinsics.height != height)) {
      throw DatasetError("camera info '" + options.camera_info_path + "' is for " +
                         std::to_string(intrinsics.width) + "x" +
                         std::to_string(intrinsics.height) + " images, the dataset's are " +
                         std::to_string(width) + "x" + std::to_string(height));
    }
  }
  intrinsics.width = width;
  intrinsics.height = height;
  return intrinsics;
}

void FillCameraInfo(const Intrinsics& intrinsics, double depth_scale, msgs::CameraInfo& out) {
  out.width = intrinsics.width;
  out.height = intrinsics.height;
  out.fx = intrinsics.fx;
  out.fy = intrinsics.fy;
  out.cx = intrinsics.cx;
  out.cy = intrinsics.cy;
  out.distortion_model = intrinsics.model;
  out.distortion_count = static_cast<uint32_t>(intrinsics.distortion.size());
  for (size_t i = 0; i < intrinsics.distortion.size() && i < msgs::kMaxDistortionCoefficients;
       ++i) {
    out.distortion[i] = intrinsics.distortion[i];
  }
  out.depth_scale = depth_scale;
}

}  // namespace probeless::dataset::internal

namespace probeless::dataset::internal {

StreamMessage CameraInfoMessage(size_t topic_index, uint64_t log_time_ns,
                                const Intrinsics& intrinsics, double depth_scale, int64_t stamp_ns,
                                uint64_t sequence, std::string_view frame_id) {
  StreamMessage message = NewMessage(topic_index, log_time_ns, sizeof(msgs::CameraInfo));
  msgs::WriteView<msgs::CameraInfo> view =
      msgs::WriteMessage<msgs::CameraInfo>(message.message.bytes());
  FillHeader(view->header, stamp_ns, sequence, frame_id);
  FillCameraInfo(intrinsics, depth_scale, *view);
  return message;
}

}  // namespace probeless::dataset::internal
