#include "probeless/face_track/sampling.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "probeless/msgs/face_observation.h"
#include "probeless/msgs/image.h"

namespace probeless::face_track {

namespace fl = face_light;

namespace {

// Canonical crop pixels -> face frame (mm): the crop's eye centres (32, 44) / (133, 44) are the
// generic model's eye centres (-32, 1, _) / (32, 1, _) mm.
constexpr double kMmPerCropPixel = 64.0 / 101.0;
constexpr double kCropCentreX = 82.5, kCropEyeY = 44, kEyeYmm = 1;
// Ellipsoid head surface (mm, face frame): centre and semi-axes.
constexpr double kEllCx = 0, kEllCy = 35, kEllCz = 80;
constexpr double kEllA = 78, kEllB = 110, kEllC = 95;

}  // namespace

int FaceSamples::ValidCount() const {
  return static_cast<int>(std::count(flags.begin(), flags.end(), 0));
}

std::array<fl::Point2, 4> CanonicalLandmarks(std::span<const Point2f> p) {
  if (p.size() != kLandmarkCount) {
    throw FaceTrackError("CanonicalLandmarks: expected 68 landmarks, got " +
                         std::to_string(p.size()));
  }
  std::array<fl::Point2, 4> out{};
  for (int i = 0; i < 6; ++i) {
    out[0].x += p[36 + i].x / 6.0;
    out[0].y += p[36 + i].y / 6.0;
    out[1].x += p[42 + i].x / 6.0;
    out[1].y += p[42 + i].y / 6.0;
  }
  out[2] = {p[30].x, p[30].y};
  for (int i = 60; i < 68; ++i) {
    out[3].x += p[i].x / 8.0;
    out[3].y += p[i].y / 8.0;
  }
  return out;
}

FaceSampler::FaceSampler(const fl::FaceLightModel& model, const SamplerOptions& options)
    : model_(model), options_(options), positions_(model.positions) {
  try {
    model_.Validate();
  } catch (const fl::FaceLightError& e) {
    throw FaceTrackError(std::string("face sampler: invalid model: ") + e.what());
  }
  if (options.saturation_level < 0 || options.saturation_level > 256) {
    throw FaceTrackError("saturation_level must be in 0..256");
  }
  if (!(options.dark_level >= 0 && options.dark_level < 1)) {
    throw FaceTrackError("dark_level must be in [0, 1)");
  }
  if (!(options.min_facing_cosine >= -1 && options.min_facing_cosine <= 1)) {
    throw FaceTrackError("min_facing_cosine must be in [-1, 1]");
  }
  if (!(options.neighbour_threshold >= 0) || options.neighbours < 2 || options.neighbours > 16) {
    throw FaceTrackError("neighbour_threshold must be >= 0 and neighbours in 2..16");
  }
  const int n = SampleCount();
  std::vector<fl::Point2> crop(n);
  for (int i = 0; i < n; ++i) {
    crop[i] = fl::CropPixelFromNormalised(positions_[i]);
    const double x = (crop[i].x - kCropCentreX) * kMmPerCropPixel;
    const double y = (crop[i].y - kCropEyeY) * kMmPerCropPixel + kEyeYmm;
    const double qx = (x - kEllCx) / kEllA, qy = (y - kEllCy) / kEllB;
    const double q = std::min(0.999, qx * qx + qy * qy);
    const double z = kEllCz - kEllC * std::sqrt(1 - q);
    std::array<double, 3> normal{(x - kEllCx) / (kEllA * kEllA), (y - kEllCy) / (kEllB * kEllB),
                                 (z - kEllCz) / (kEllC * kEllC)};
    const double len =
        std::sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]);
    for (double& v : normal) v /= len;
    points_.push_back({x * 1e-3, y * 1e-3, z * 1e-3});
    normals_.push_back(normal);
  }
  const int k = std::min(options.neighbours, n - 1);
  options_.neighbours = std::max(k, 0);
  neighbours_.assign(static_cast<size_t>(n) * options_.neighbours, 0);
  std::vector<int> order(n);
  for (int i = 0; i < n; ++i) {
    std::iota(order.begin(), order.end(), 0);
    auto d2 = [&](int j) {
      return (crop[j].x - crop[i].x) * (crop[j].x - crop[i].x) +
             (crop[j].y - crop[i].y) * (crop[j].y - crop[i].y);
    };
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return d2(a) < d2(b); });
    for (int m = 0; m < options_.neighbours; ++m)
      neighbours_[i * options_.neighbours + m] = order[m + 1];
  }
}

fl::SimilarityTransform CanonicalToImage(std::span<const Point2f> landmarks, bool four_point) {
  const auto live = CanonicalLandmarks(landmarks);
  const size_t used = four_point ? 4 : 2;
  return fl::FitSimilarity(std::span(kTrackerCanonical.data(), used), std::span(live.data(), used));
}

FaceSamples FaceSampler::Sample(const ImageView& image, const FaceTrack& track) const {
  if (!track.found) throw FaceTrackError("face sampler: no face in this track");
  if (!image.data || image.width <= 0 || image.height <= 0) {
    throw FaceTrackError("face sampler: empty image");
  }
  const int n = SampleCount();
  FaceSamples out;
  out.count = n;
  out.rgb.assign(3 * n, 0.f);
  out.flags.assign(n, 0);
  out.normals.assign(3 * n, 0.f);
  out.image_points.assign(2 * n, 0.f);

  const auto live = CanonicalLandmarks(track.landmarks);
  const std::array<fl::Point2, 4> canonical = kTrackerCanonical;
  const size_t used = options_.four_point_frame ? 4 : 2;
  out.crop_to_image = CanonicalToImage(track.landmarks, options_.four_point_frame);
  double residual = 0;
  for (size_t i = 0; i < used; ++i) {
    const fl::Point2 p = out.crop_to_image.Apply(canonical[i]);
    residual += (p.x - live[i].x) * (p.x - live[i].x) + (p.y - live[i].y) * (p.y - live[i].y);
  }
  const double fit_rms = std::sqrt(residual / used);
  const double iod = std::hypot(live[1].x - live[0].x, live[1].y - live[0].y);

  // Patches, per channel.
  const int channels = image.Channels();
  std::vector<float> values(static_cast<size_t>(n) * channels);
  std::vector<uint8_t> valid(n);
  fl::SamplePatches(image.data, image.width, image.height, image.stride, channels,
                    out.crop_to_image, positions_, model_.patch_radius_px,
                    options_.saturation_level, values, valid);
  const int r = static_cast<int>(std::lround(model_.patch_radius_px * out.crop_to_image.Scale()));
  std::vector<float> mean(n);
  for (int i = 0; i < n; ++i) {
    float* rgb = &out.rgb[3 * i];
    if (channels == 1) {
      rgb[0] = rgb[1] = rgb[2] = values[i];
    } else if (image.format == PixelFormat::kBgr) {
      rgb[0] = values[3 * i + 2];
      rgb[1] = values[3 * i + 1];
      rgb[2] = values[3 * i];
    } else {
      std::copy_n(&values[3 * i], 3, rgb);
    }
    if (options_.srgb_input) {
      // Decoding the patch mean, not each pixel: a slight underestimate on textured patches.
      for (int c = 0; c < 3; ++c) {
        rgb[c] = rgb[c] <= 0.04045f ? rgb[c] / 12.92f : std::pow((rgb[c] + 0.055f) / 1.055f, 2.4f);
      }
    }
    mean[i] = (rgb[0] + rgb[1] + rgb[2]) / 3;
    const fl::Point2 c = out.crop_to_image.Apply(fl::CropPixelFromNormalised(positions_[i]));
    out.image_points[2 * i] = static_cast<float>(c.x);
    out.image_points[2 * i + 1] = static_cast<float>(c.y);
    if (!valid[i]) {
      const long cx = std::lround(c.x), cy = std::lround(c.y);
      const bool outside =
          cx - r < 0 || cy - r < 0 || cx + r >= image.width || cy + r >= image.height;
      out.flags[i] |= outside ? kOutsideImage : kSaturated;
    }
    if (mean[i] < options_.dark_level) out.flags[i] |= kTooDark;
  }
  // Normals in the camera frame and pose occlusion.
  const HeadPose& pose = track.pose;
  for (int i = 0; i < n; ++i) {
    const auto& nf = normals_[i];
    const auto& pf = points_[i];
    std::array<double, 3> nc{}, pc{};
    for (int a = 0; a < 3; ++a) {
      nc[a] = pose.rotation[3 * a] * nf[0] + pose.rotation[3 * a + 1] * nf[1] +
              pose.rotation[3 * a + 2] * nf[2];
      pc[a] = pose.rotation[3 * a] * pf[0] + pose.rotation[3 * a + 1] * pf[1] +
              pose.rotation[3 * a + 2] * pf[2] + pose.translation[a];
    }
    for (int a = 0; a < 3; ++a) out.normals[3 * i + a] = static_cast<float>(nc[a]);
    if (pose.valid) {
      const double len = std::sqrt(pc[0] * pc[0] + pc[1] * pc[1] + pc[2] * pc[2]);
      const double facing = -(nc[0] * pc[0] + nc[1] * pc[1] + nc[2] * pc[2]) / len;
      if (facing < options_.min_facing_cosine) out.flags[i] |= kFacingAway;
    }
  }
  // Neighbour consistency on the samples valid so far.
  if (options_.neighbour_threshold > 0 && options_.neighbours >= 2) {
    std::vector<uint8_t> inconsistent(n, 0);
    float buffer[16];
    for (int i = 0; i < n; ++i) {
      if (out.flags[i]) continue;
      int m = 0;
      for (int k = 0; k < options_.neighbours; ++k) {
        const int j = neighbours_[i * options_.neighbours + k];
        if (!out.flags[j]) buffer[m++] = mean[j];
      }
      if (m < 3) continue;
      std::nth_element(buffer, buffer + m / 2, buffer + m);
      const float median = buffer[m / 2];
      if (std::abs(mean[i] - median) > options_.neighbour_threshold) inconsistent[i] = 1;
    }
    for (int i = 0; i < n; ++i) {
      if (inconsistent[i]) out.flags[i] |= kInconsistent;
    }
  }
  const double fit_term = iod > 0 ? std::clamp(1 - fit_rms / (0.05 * iod), 0.0, 1.0) : 0.0;
  out.quality = static_cast<float>(static_cast<double>(out.ValidCount()) / n * fit_term *
                                   std::clamp(static_cast<double>(track.confidence), 0.0, 1.0));
  return out;
}

ImageView ViewOfImage(const msgs::Image& image, std::span<const std::byte> payload) {
  image.Validate(payload.size());
  ImageView view{reinterpret_cast<const uint8_t*>(payload.data()), static_cast<int>(image.width),
                 static_cast<int>(image.height), image.step, PixelFormat::kGray};
  switch (image.encoding) {
    case msgs::Encoding::kMono8:
      break;
    case msgs::Encoding::kRgb8:
      view.format = PixelFormat::kRgb;
      break;
    case msgs::Encoding::kBgr8:
      view.format = PixelFormat::kBgr;
      break;
    default:
      throw msgs::MessageError("face_tracker: image encoding " +
                               std::string(msgs::EncodingName(image.encoding)) +
                               " not supported (expected rgb8, bgr8 or mono8)");
  }
  return view;
}

void FillObservation(const FaceTrack& track, const FaceSamples* samples,
                     msgs::FaceObservation& out) {
  const msgs::Header header = out.header;
  out = msgs::FaceObservation{};
  out.header = header;
  if (!track.found) return;
  out.face_detected = 1;
  out.landmark_count = kLandmarkCount;
  for (int i = 0; i < kLandmarkCount; ++i) {
    out.landmarks[i][0] = track.landmarks[i].x;
    out.landmarks[i][1] = track.landmarks[i].y;
  }
  if (track.pose.valid) {
    const auto q = QuaternionFromMatrix(track.pose.rotation);
    out.head_pose.rotation = {q[0], q[1], q[2], q[3]};  // w, x, y, z
    out.head_pose.translation = {track.pose.translation[0], track.pose.translation[1],
                                 track.pose.translation[2]};
  } else {
    out.head_pose.rotation = {1, 0, 0, 0};
  }
  if (!samples) return;
  const int n = std::min<int>(samples->count, msgs::kMaxFaceSamples);
  out.sample_count = static_cast<uint32_t>(n);
  for (int i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) {
      out.sample_rgb[i][c] = samples->rgb[3 * i + c];
      out.sample_normals[i][c] = samples->normals[3 * i + c];
    }
    out.SetSampleValid(static_cast<uint32_t>(i), samples->flags[i] == 0);
  }
  out.quality = std::clamp(samples->quality, 0.f, 1.f);
}

void DrawDebugImage(const ImageView& image, const FaceTrack& track, const FaceSamples& samples,
                    const Intrinsics& intrinsics, std::vector<uint8_t>& out) {
  out.resize(static_cast<size_t>(image.width) * image.height * 3);
  cv::Mat rgb(image.height, image.width, CV_8UC3, out.data());
  const cv::Mat in(image.height, image.width,
                   image.format == PixelFormat::kGray ? CV_8UC1 : CV_8UC3,
                   const_cast<uint8_t*>(image.data), image.stride);
  switch (image.format) {
    case PixelFormat::kGray:
      cv::cvtColor(in, rgb, cv::COLOR_GRAY2RGB);
      break;
    case PixelFormat::kRgb:
      in.copyTo(rgb);
      break;
    case PixelFormat::kBgr:
      cv::cvtColor(in, rgb, cv::COLOR_BGR2RGB);
      break;
  }
  if (!track.found) return;
  const int half = std::max(1, static_cast<int>(std::lround(2 * samples.crop_to_image.Scale())));
  for (int i = 0; i < samples.count; ++i) {
    const cv::Point c(static_cast<int>(std::lround(samples.image_points[2 * i])),
                      static_cast<int>(std::lround(samples.image_points[2 * i + 1])));
    const cv::Scalar colour = samples.flags[i] ? cv::Scalar(255, 40, 40) : cv::Scalar(40, 255, 40);
    cv::rectangle(rgb, c - cv::Point(half, half), c + cv::Point(half, half), colour, 1);
  }
  for (int i = 0; i < kLandmarkCount; ++i) {
    cv::circle(rgb,
               cv::Point(static_cast<int>(std::lround(track.landmarks[i].x)),
                         static_cast<int>(std::lround(track.landmarks[i].y))),
               1, cv::Scalar(255, 255, 0), cv::FILLED);
  }
  if (track.pose.valid && intrinsics.fx > 0) {
    auto project = [&](double x, double y, double z) {
      const auto& r = track.pose.rotation;
      const auto& t = track.pose.translation;
      const double px = r[0] * x + r[1] * y + r[2] * z + t[0];
      const double py = r[3] * x + r[4] * y + r[5] * z + t[1];
      const double pz = std::max(1e-3, r[6] * x + r[7] * y + r[8] * z + t[2]);
      return cv::Point(static_cast<int>(std::lround(intrinsics.fx * px / pz + intrinsics.cx)),
                       static_cast<int>(std::lround(intrinsics.fy * py / pz + intrinsics.cy)));
    };
    const cv::Point o = project(0, 0, 0);
    cv::line(rgb, o, project(0.05, 0, 0), cv::Scalar(255, 0, 0), 2);
    cv::line(rgb, o, project(0, 0.05, 0), cv::Scalar(0, 255, 0), 2);
    cv::line(rgb, o, project(0, 0, -0.05), cv::Scalar(0, 0, 255), 2);
  }
}

}  // namespace probeless::face_track
