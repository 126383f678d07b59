#include "probeless/face_track/head_model.h"

#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <vector>

namespace probeless::face_track {

// Face frame, millimetres (x subject's left, y chin, z into the head). Right = subject's right =
// image left for a frontal face = negative x.
const std::array<std::array<float, 3>, kLandmarkCount> kGenericLandmarksMm = {{
    // 0..16 jaw line, from the subject's right (image left) to the left
    {-70, 10, 75},
    {-68, 28, 72},
    {-64, 46, 67},
    {-58, 62, 60},
    {-50, 77, 50},
    {-39, 89, 38},
    {-27, 98, 27},
    {-14, 104, 19},
    {0, 106, 16},
    {14, 104, 19},
    {27, 98, 27},
    {39, 89, 38},
    {50, 77, 50},
    {58, 62, 60},
    {64, 46, 67},
    {68, 28, 72},
    {70, 10, 75},
    // 17..21 right eyebrow (outer -> inner), 22..26 left eyebrow (inner -> outer)
    {-56, -12, 18},
    {-47, -20, 8},
    {-36, -24, 2},
    {-24, -24, -2},
    {-12, -20, -4},
    {12, -20, -4},
    {24, -24, -2},
    {36, -24, 2},
    {47, -20, 8},
    {56, -12, 18},
    // 27..30 nose bridge to tip, 31..35 nostrils and base (subject's right -> left)
    {0, -2, 0},
    {0, 10, -7},
    {0, 21, -14},
    {0, 32, -22},
    {-14, 40, -4},
    {-7, 42, -9},
    {0, 44, -12},
    {7, 42, -9},
    {14, 40, -4},
    // 36..41 right eye (outer corner, upper lid, inner corner, lower lid)
    {-45, 2, 12},
    {-37, -4, 7},
    {-27, -4, 7},
    {-19, 2, 9},
    {-27, 5, 8},
    {-37, 5, 8},
    // 42..47 left eye (inner corner, upper lid, outer corner, lower lid)
    {19, 2, 9},
    {27, -4, 7},
    {37, -4, 7},
    {45, 2, 12},
    {37, 5, 8},
    {27, 5, 8},
    // 48..59 outer lips (right corner, upper lip, left corner, lower lip)
    {-25, 67, 8},
    {-15, 61, -2},
    {-6, 58, -6},
    {0, 59, -7},
    {6, 58, -6},
    {15, 61, -2},
    {25, 67, 8},
    {15, 74, 0},
    {7, 77, -4},
    {0, 78, -5},
    {-7, 77, -4},
    {-15, 74, 0},
    // 60..67 inner lips
    {-20, 67, 5},
    {-7, 64, -3},
    {0, 64, -4},
    {7, 64, -3},
    {20, 67, 5},
    {7, 68, -3},
    {0, 68, -4},
    {-7, 68, -3},
}};

HeadPose EstimateHeadPose(std::span<const Point2f> landmarks, double fx, double fy, double cx,
                          double cy, const HeadPose& guess, double* rms_px) {
  HeadPose pose;
  if (landmarks.size() != kLandmarkCount || !(fx > 0) || !(fy > 0)) return pose;
  std::vector<cv::Point3d> object(kLandmarkCount);
  std::vector<cv::Point2d> image(kLandmarkCount);
  for (int i = 0; i < kLandmarkCount; ++i) {
    object[i] = {kGenericLandmarksMm[i][0] * 1e-3, kGenericLandmarksMm[i][1] * 1e-3,
                 kGenericLandmarksMm[i][2] * 1e-3};
    image[i] = {landmarks[i].x, landmarks[i].y};
  }
  const cv::Matx33d k(fx, 0, cx, 0, fy, cy, 0, 0, 1);
  cv::Mat rvec, tvec;
  bool ok = false;
  try {
    if (guess.valid) {
      cv::Matx33d r(guess.rotation.data());
      cv::Rodrigues(r, rvec);
      tvec = (cv::Mat_<double>(3, 1) << guess.translation[0], guess.translation[1],
              guess.translation[2]);
      ok = cv::solvePnP(object, image, k, cv::noArray(), rvec, tvec, true, cv::SOLVEPNP_ITERATIVE);
    } else {
      ok = cv::solvePnP(object, image, k, cv::noArray(), rvec, tvec, false, cv::SOLVEPNP_EPNP);
      if (ok) {
        ok =
            cv::solvePnP(object, image, k, cv::noArray(), rvec, tvec, true, cv::SOLVEPNP_ITERATIVE);
      }
    }
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok || tvec.at<double>(2) <= 0) return pose;
  cv::Matx33d r;
  cv::Rodrigues(rvec, r);
  for (int i = 0; i < 9; ++i) pose.rotation[i] = r.val[i];
  for (int i = 0; i < 3; ++i) pose.translation[i] = tvec.at<double>(i);
  pose.valid = std::isfinite(pose.translation[2]);
  if (rms_px) {
    std::vector<cv::Point2d> projected;
    cv::projectPoints(object, rvec, tvec, k, cv::noArray(), projected);
    double sum = 0;
    for (int i = 0; i < kLandmarkCount; ++i) {
      const cv::Point2d d = projected[i] - image[i];
      sum += d.dot(d);
    }
    *rms_px = std::sqrt(sum / kLandmarkCount);
  }
  return pose;
}

std::array<double, 4> QuaternionFromMatrix(const std::array<double, 9>& m) {
  std::array<double, 4> q{};
  const double trace = m[0] + m[4] + m[8];
  if (trace > 0) {
    const double s = 2 * std::sqrt(trace + 1);
    q = {0.25 * s, (m[7] - m[5]) / s, (m[2] - m[6]) / s, (m[3] - m[1]) / s};
  } else if (m[0] > m[4] && m[0] > m[8]) {
    const double s = 2 * std::sqrt(1 + m[0] - m[4] - m[8]);
    q = {(m[7] - m[5]) / s, 0.25 * s, (m[1] + m[3]) / s, (m[2] + m[6]) / s};
  } else if (m[4] > m[8]) {
    const double s = 2 * std::sqrt(1 + m[4] - m[0] - m[8]);
    q = {(m[2] - m[6]) / s, (m[1] + m[3]) / s, 0.25 * s, (m[5] + m[7]) / s};
  } else {
    const double s = 2 * std::sqrt(1 + m[8] - m[0] - m[4]);
    q = {(m[3] - m[1]) / s, (m[2] + m[6]) / s, (m[5] + m[7]) / s, 0.25 * s};
  }
  if (q[0] < 0) {
    for (double& v : q) v = -v;
  }
  const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (double& v : q) v /= n;
  return q;
}

std::array<double, 9> MatrixFromQuaternion(const std::array<double, 4>& q) {
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  return {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
          2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
          2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
}

HeadPose PoseFilter::Update(const HeadPose& measured) {
  if (!measured.valid) return measured;
  if (!state_.valid || smoothing_ <= 0) {
    state_ = measured;
    return state_;
  }
  auto qa = QuaternionFromMatrix(state_.rotation);
  auto qb = QuaternionFromMatrix(measured.rotation);
  double dot = 0;
  for (int i = 0; i < 4; ++i) dot += qa[i] * qb[i];
  if (dot < 0) {
    for (double& v : qb) v = -v;
    dot = -dot;
  }
  const double angle = 2 * std::acos(std::min(1.0, dot));
  double jump = 0;
  for (int i = 0; i < 3; ++i) {
    jump += (state_.translation[i] - measured.translation[i]) *
            (state_.translation[i] - measured.translation[i]);
  }
  if (angle > 25 * M_PI / 180 || std::sqrt(jump) > 0.1) {
    state_ = measured;
    return state_;
  }
  const double a = smoothing_;
  std::array<double, 4> q{};
  double n = 0;
  for (int i = 0; i < 4; ++i) {
    q[i] = a * qa[i] + (1 - a) * qb[i];
    n += q[i] * q[i];
  }
  for (double& v : q) v /= std::sqrt(n);
  state_.rotation = MatrixFromQuaternion(q);
  for (int i = 0; i < 3; ++i) {
    state_.translation[i] = a * state_.translation[i] + (1 - a) * measured.translation[i];
  }
  return state_;
}

}  // namespace probeless::face_track
