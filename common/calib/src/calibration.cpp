#include "probeless/calib/calibration.h"

#include <yaml-cpp/yaml.h>

#include <cctype>
#include <cmath>
#include <fstream>
#include <initializer_list>
#include <iomanip>
#include <numbers>
#include <opencv2/core.hpp>
#include <sstream>
#include <string_view>

namespace probeless::calib {

namespace {

// "calibration file '<path>'" followed by `what` (which starts with ": " or " ").
[[noreturn]] void Fail(const std::string& path, const std::string& what) {
  throw CalibrationError("calibration file '" + path + "'" + what);
}

// Sets model and coefficients from 0, 4 (k3 = 0 added), 5 or 8 coefficients.
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
      Fail(path, " has " + std::to_string(coefficients.size()) +
                     " distortion coefficients: expected 0, 4, 5 (plumb_bob) or 8 "
                     "(rational_polynomial)");
  }
  intrinsics.distortion = std::move(coefficients);
}

void SetMatrix(Intrinsics& intrinsics, const std::vector<double>& k, const std::string& path) {
  if (k.size() != 9) {
    Fail(path, ": camera matrix has " + std::to_string(k.size()) + " entries, expected 9 (3x3)");
  }
  intrinsics.fx = k[0];
  intrinsics.fy = k[4];
  intrinsics.cx = k[2];
  intrinsics.cy = k[5];
  if (!(intrinsics.fx > 0) || !(intrinsics.fy > 0)) {
    Fail(path, ": camera matrix must have positive focal lengths fx, fy");
  }
}

uint32_t CheckedSize(double value, const std::string& path, std::string_view key) {
  if (!(value >= 0) || value > 1e6 || value != std::floor(value)) {
    Fail(path, ": " + std::string(key) + " must be a non-negative whole number of pixels");
  }
  return static_cast<uint32_t>(value);
}

Intrinsics ReadRosYaml(const std::string& path, const std::string& text) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    Fail(path, " is not valid YAML: " + std::string(e.what()));
  }
  if (!root.IsMap()) {
    Fail(path, ": expected a ROS camera_info YAML mapping (camera_matrix, ...)");
  }
  Intrinsics intrinsics;
  try {
    auto data_of = [&](std::string_view key) -> std::vector<double> {
      const YAML::Node node = root[std::string(key)];
      if (!node) return {};
      const YAML::Node data = node["data"];
      if (!data || !data.IsSequence()) Fail(path, ": " + std::string(key) + " needs a data list");
      return data.as<std::vector<double>>();
    };
    if (!root["camera_matrix"]) {
      Fail(path, ": missing camera_matrix (expected a ROS camera_info YAML file)");
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
      Fail(path, ": distortion_model '" + model +
                     "' is not supported (expected plumb_bob or rational_polynomial)");
    }
    SetDistortion(intrinsics, std::move(coefficients), path);
    if (model == "rational_polynomial" &&
        intrinsics.model != msgs::DistortionModel::kRationalPolynomial &&
        intrinsics.model != msgs::DistortionModel::kNone) {
      Fail(path, ": rational_polynomial needs 8 distortion coefficients");
    }
  } catch (const YAML::Exception& e) {
    Fail(path, ": malformed entry: " + std::string(e.what()));
  }
  return intrinsics;
}

Intrinsics ReadFileStorageOrThrow(const std::string& path) {
  cv::FileStorage storage;
  try {
    storage.open(path, cv::FileStorage::READ);
  } catch (const cv::Exception&) {
    // Reported below: the storage is not open.
  }
  if (!storage.isOpened()) Fail(path, " is not a readable OpenCV FileStorage YAML/XML file");
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
    if (mat.empty()) Fail(path, ": " + std::string(what) + " is not an opencv-matrix");
    cv::Mat as_double;
    mat.convertTo(as_double, CV_64F);
    std::vector<double> values;
    for (int r = 0; r < as_double.rows; ++r) {
      for (int c = 0; c < as_double.cols; ++c) values.push_back(as_double.at<double>(r, c));
    }
    return values;
  };
  Intrinsics intrinsics;
  const cv::FileNode k = find({"camera_matrix", "cameraMatrix", "K"});
  if (k.empty()) {
    Fail(path, ": missing camera_matrix (or cameraMatrix, K) in OpenCV FileStorage file");
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

// OpenCV's parser lets standard exceptions out of corrupt files (a std::length_error from a
// garbled scalar, found by calibration_fuzz): bad input, reported as such.
Intrinsics ReadFileStorage(const std::string& path) {
  try {
    return ReadFileStorageOrThrow(path);
  } catch (const CalibrationError&) {
    throw;
  } catch (const std::exception& e) {
    Fail(path,
         " is not a readable OpenCV FileStorage YAML/XML file (" + std::string(e.what()) + ")");
  }
}

}  // namespace

Intrinsics ReadCalibrationFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw CalibrationError("cannot read calibration file '" + path + "'");
  std::ostringstream buffer;
  buffer << in.rdbuf();
  if (in.bad()) throw CalibrationError("cannot read calibration file '" + path + "'");
  const std::string text = buffer.str();
  size_t start = 0;
  while (start < text.size() && std::isspace(static_cast<unsigned char>(text[start]))) ++start;
  const std::string_view head = std::string_view(text).substr(start);
  if (head.starts_with("%YAML:1") || head.starts_with("<?xml") ||
      head.starts_with("<opencv_storage")) {
    return ReadFileStorage(path);
  }
  return ReadRosYaml(path, text);
}

std::string CameraInfoYaml(const Intrinsics& in, const std::string& camera_name) {
  std::ostringstream out;
  out << std::setprecision(10);
  auto list = [&](const std::vector<double>& v) {
    out << "[";
    for (size_t i = 0; i < v.size(); ++i) out << (i ? ", " : "") << v[i];
    out << "]";
  };
  out << "image_width: " << in.width << "\n";
  out << "image_height: " << in.height << "\n";
  out << "camera_name: " << camera_name << "\n";
  out << "camera_matrix:\n  rows: 3\n  cols: 3\n  data: ";
  list({in.fx, 0, in.cx, 0, in.fy, in.cy, 0, 0, 1});
  out << "\ndistortion_model: "
      << (in.model == msgs::DistortionModel::kRationalPolynomial ? "rational_polynomial"
                                                                 : "plumb_bob")
      << "\n";
  std::vector<double> d = in.distortion;
  if (in.model == msgs::DistortionModel::kNone) d.assign(5, 0.0);
  out << "distortion_coefficients:\n  rows: 1\n  cols: " << d.size() << "\n  data: ";
  list(d);
  out << "\nrectification_matrix:\n  rows: 3\n  cols: 3\n  data: ";
  list({1, 0, 0, 0, 1, 0, 0, 0, 1});
  out << "\nprojection_matrix:\n  rows: 3\n  cols: 4\n  data: ";
  list({in.fx, 0, in.cx, 0, 0, in.fy, in.cy, 0, 0, 0, 1, 0});
  out << "\n";
  return out.str();
}

void WriteCameraInfoYaml(const std::string& path, const Intrinsics& intrinsics,
                         const std::string& camera_name) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << CameraInfoYaml(intrinsics, camera_name);
  out.flush();
  if (!out) Fail(path, " cannot be written (check the folder exists and is writable)");
}

Intrinsics IntrinsicsFromFieldOfView(uint32_t width, uint32_t height, double horizontal_fov_deg) {
  if (!(horizontal_fov_deg > 0 && horizontal_fov_deg < 180)) {
    throw CalibrationError("field of view " + std::to_string(horizontal_fov_deg) +
                           " deg is outside (0, 180)");
  }
  Intrinsics intrinsics;
  intrinsics.width = width;
  intrinsics.height = height;
  const double focal = width / (2 * std::tan(horizontal_fov_deg / 2 * std::numbers::pi / 180.0));
  intrinsics.fx = focal;
  intrinsics.fy = focal;
  intrinsics.cx = (width - 1) / 2.0;
  intrinsics.cy = (height - 1) / 2.0;
  return intrinsics;
}

Intrinsics ScaleIntrinsics(const Intrinsics& in, uint32_t width, uint32_t height) {
  Intrinsics out = in;
  if (in.width != 0 && in.height != 0) {
    const double sx = static_cast<double>(width) / in.width;
    const double sy = static_cast<double>(height) / in.height;
    out.fx = in.fx * sx;
    out.fy = in.fy * sy;
    // Pixel centres at integers: scale about the corner of the image (-0.5, -0.5).
    out.cx = (in.cx + 0.5) * sx - 0.5;
    out.cy = (in.cy + 0.5) * sy - 0.5;
  }
  out.width = width;
  out.height = height;
  return out;
}

void FillCameraInfo(const Intrinsics& intrinsics, double depth_scale, msgs::CameraInfo& out) {
  out.width = intrinsics.width;
  out.height = intrinsics.height;
  out.fx = intrinsics.fx;
  out.fy = intrinsics.fy;
  out.cx = intrinsics.cx;
  out.cy = intrinsics.cy;
  out.distortion_model = intrinsics.model;
  out.distortion_count = 0;
  for (size_t i = 0; i < intrinsics.distortion.size() && i < msgs::kMaxDistortionCoefficients;
       ++i) {
    out.distortion[i] = intrinsics.distortion[i];
    ++out.distortion_count;
  }
  // A camera without distortion is published as ROS writes one: plumb_bob with five zeros.
  if (out.distortion_model == msgs::DistortionModel::kNone) {
    out.distortion_model = msgs::DistortionModel::kPlumbBob;
    out.distortion_count = 5;
    for (int i = 0; i < 5; ++i) out.distortion[i] = 0;
  }
  out.depth_scale = depth_scale;
}

}  // namespace probeless::calib
