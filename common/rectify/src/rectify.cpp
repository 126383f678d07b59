#include "probeless/rectify/rectify.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace probeless::rectify {
namespace {

constexpr const char* kCoefficientNames[msgs::kMaxDistortionCoefficients] = {
    "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"};

std::string Str(std::string_view s) { return std::string(s); }

std::string Size(uint32_t w, uint32_t h) { return std::to_string(w) + "x" + std::to_string(h); }

// Always-armed invariant check (not bad input: a bug).
void Check(bool ok, const char* what) {
  if (!ok) throw std::logic_error(std::string("rectify: broken invariant: ") + what);
}

cv::Matx33d CameraMatrix(const msgs::CameraInfo& info) {
  return {info.fx, 0, info.cx, 0, info.fy, info.cy, 0, 0, 1};
}

std::vector<double> Coefficients(const msgs::CameraInfo& info) {
  return {info.distortion, info.distortion + info.distortion_count};
}

// The new camera matrix: K itself, or OpenCV's free scaling by alpha.
cv::Matx33d NewCameraMatrix(const msgs::CameraInfo& info, const RectifyOptions& options) {
  const cv::Matx33d k = CameraMatrix(info);
  if (options.alpha < 0 || !HasDistortion(info)) return k;
  const cv::Size size(static_cast<int>(info.width), static_cast<int>(info.height));
  const cv::Mat m = cv::getOptimalNewCameraMatrix(k, Coefficients(info), size, options.alpha, size);
  return cv::Matx33d(m);
}

void ValidateOptions(const RectifyOptions& options, std::string_view source) {
  if (!(options.alpha <= 1) || std::isnan(options.alpha)) {
    throw RectifyError(Str(source) + ": alpha " + std::to_string(options.alpha) +
                       " is outside [0, 1] (or < 0 to keep the camera matrix)");
  }
  if (!(options.depth_edge_tolerance > 0) || !std::isfinite(options.depth_edge_tolerance)) {
    throw RectifyError(Str(source) + ": depth_edge_tolerance must be > 0");
  }
}

bool IsDepth(msgs::Encoding e) {
  return e == msgs::Encoding::kDepth16 || e == msgs::Encoding::kFloat32;
}

int CvType(msgs::Encoding e) {
  switch (e) {
    case msgs::Encoding::kRgb8:
    case msgs::Encoding::kBgr8:
      return CV_8UC3;
    case msgs::Encoding::kMono8:
      return CV_8UC1;
    case msgs::Encoding::kMono16:
    case msgs::Encoding::kDepth16:
      return CV_16UC1;
    case msgs::Encoding::kFloat32:
      return CV_32FC1;
    case msgs::Encoding::kRgb32f:
      return CV_32FC3;
    case msgs::Encoding::kInvalid:
      break;
  }
  return -1;
}

bool ValidDepth(uint16_t d) { return d != 0; }
bool ValidDepth(float d) { return d > 0 && std::isfinite(d); }

// `out` set up for a copy of `in` (header, size, encoding, packed step); the input and output
// buffers checked. Throws RectifyError "<name>: ...".
void PrepareOutput(const msgs::Image& in, std::span<const std::byte> in_pixels, msgs::Image& out,
                   std::span<std::byte> out_pixels, const std::string& name) {
  try {
    in.Validate(in_pixels.size());
  } catch (const std::exception& e) {
    throw RectifyError(name + ": " + e.what());
  }
  const msgs::Header header = in.header;
  out.Init(in.width, in.height, in.encoding);
  out.header = header;
  if (out_pixels.size() < out.PayloadBytes()) {
    throw RectifyError(name + ": output buffer of " + std::to_string(out_pixels.size()) +
                       " bytes, " + std::to_string(out.PayloadBytes()) + " needed");
  }
}

// The rows of `in` into `out`'s packed rows (both prepared by PrepareOutput).
void CopyRows(const msgs::Image& in, std::span<const std::byte> in_pixels, const msgs::Image& out,
              std::span<std::byte> out_pixels) {
  for (uint32_t y = 0; y < in.height; ++y) {
    std::memcpy(out_pixels.data() + y * static_cast<size_t>(out.step),
                in_pixels.data() + y * static_cast<size_t>(in.step), out.step);
  }
}

}  // namespace

bool HasDistortion(const msgs::CameraInfo& info) {
  for (uint32_t i = 0; i < info.distortion_count && i < msgs::kMaxDistortionCoefficients; ++i) {
    if (info.distortion[i] != 0) return true;
  }
  return false;
}

void ValidateCameraInfo(const msgs::CameraInfo& info, std::string_view source) {
  const std::string name = Str(source);
  const std::string_view model = msgs::DistortionModelName(info.distortion_model);
  if (model == "invalid") {
    throw RectifyError(name + ": invalid distortion model " +
                       std::to_string(static_cast<uint32_t>(info.distortion_model)) +
                       " (expected none, plumb_bob or rational_polynomial)");
  }
  const uint32_t expected = msgs::DistortionCoefficientCount(info.distortion_model);
  if (info.distortion_count != expected) {
    throw RectifyError(name + ": distortion model " + Str(model) + " has " +
                       std::to_string(expected) + " coefficients, distortion_count is " +
                       std::to_string(info.distortion_count));
  }
  for (uint32_t i = 0; i < expected; ++i) {
    if (!std::isfinite(info.distortion[i])) {
      throw RectifyError(name + ": distortion coefficient " + std::to_string(i) + " (" +
                         kCoefficientNames[i] + ") is " +
                         (std::isnan(info.distortion[i]) ? "NaN" : "infinite"));
    }
  }
  if (info.width == 0 || info.height == 0) {
    throw RectifyError(name + ": image size " + Size(info.width, info.height) +
                       " (width and height must be > 0)");
  }
  if (!(info.fx > 0) || !(info.fy > 0) || !std::isfinite(info.fx) || !std::isfinite(info.fy)) {
    throw RectifyError(name + ": fx and fy must be finite and > 0");
  }
  if (!std::isfinite(info.cx) || !std::isfinite(info.cy)) {
    throw RectifyError(name + ": the principal point (cx, cy) must be finite");
  }
}

msgs::CameraInfo RectifiedCameraInfo(const msgs::CameraInfo& info, const RectifyOptions& options,
                                     std::string_view source) {
  ValidateCameraInfo(info, source);
  ValidateOptions(options, source);
  const cv::Matx33d k = NewCameraMatrix(info, options);
  msgs::CameraInfo out = info;
  out.fx = k(0, 0);
  out.fy = k(1, 1);
  out.cx = k(0, 2);
  out.cy = k(1, 2);
  out.distortion_model = msgs::DistortionModel::kPlumbBob;
  out.distortion_count = 5;
  std::fill(std::begin(out.distortion), std::end(out.distortion), 0.0);
  return out;
}

void SetThreads(int threads) { cv::setNumThreads(std::max(1, threads)); }

struct Rectifier::Impl {
  msgs::CameraInfo calibration;  // as given (the cache key)
  msgs::CameraInfo rectified;
  RectifyOptions options;
  std::string source;
  bool passthrough = false;
  cv::Mat map_x, map_y;         // CV_32FC1 source pixel per rectified pixel
  cv::Mat map_fixed, map_frac;  // the same in OpenCV's fixed point (bilinear remap)
  // Depth: per rectified pixel the nearest source pixel (x, y; x = -1 outside) and, for
  // kEdgeAware, the top-left of its four bilinear neighbours (x = -1 unless all four are inside)
  // with the bilinear fractions. Pixel pairs, not indices: the source's row step is per image.
  std::vector<std::array<int16_t, 2>> nearest;
  std::vector<std::array<int16_t, 2>> corner;
  std::vector<std::array<float, 2>> fraction;

  template <typename T>
  void ResampleDepth(const std::byte* src, size_t src_step, std::byte* dst) const {
    if (options.depth_interpolation == DepthInterpolation::kEdgeAware) {
      ResampleDepthAs<T, true>(src, src_step, dst);
    } else {
      ResampleDepthAs<T, false>(src, src_step, dst);
    }
  }

  // One loop per mode and type: the per-pixel work is a few loads, so branches and libm calls
  // would dominate (lround cost more than the rest of the edge-aware sample).
  template <typename T, bool kEdgeAware>
  void ResampleDepthAs(const std::byte* src, size_t src_step, std::byte* dst) const {
    const uint32_t w = calibration.width, h = calibration.height;
    // msgs::Image::Validate guarantees a step that is a multiple of the channel size.
    const T* base = reinterpret_cast<const T*>(src);
    const size_t stride = src_step / sizeof(T);
    const float tolerance = static_cast<float>(options.depth_edge_tolerance);
    T* out = reinterpret_cast<T*>(dst);
    const size_t count = static_cast<size_t>(w) * h;
    for (size_t i = 0; i < count; ++i) {
      const std::array<int16_t, 2> n = nearest[i];
      T value = n[0] < 0 ? T{0} : base[static_cast<size_t>(n[1]) * stride + n[0]];
      if constexpr (kEdgeAware) {
        const std::array<int16_t, 2> c = corner[i];
        if (c[0] >= 0) {
          const T* r0 = base + static_cast<size_t>(c[1]) * stride + c[0];
          const T* r1 = r0 + stride;
          const T d00 = r0[0], d01 = r0[1], d10 = r1[0], d11 = r1[1];
          if (ValidDepth(d00) && ValidDepth(d01) && ValidDepth(d10) && ValidDepth(d11)) {
            const float lo = static_cast<float>(std::min(std::min(d00, d01), std::min(d10, d11)));
            const float hi = static_cast<float>(std::max(std::max(d00, d01), std::max(d10, d11)));
            if (hi - lo <= tolerance * lo) {
              const auto [fx, fy] = fraction[i];
              const float top = static_cast<float>(d00) + fx * static_cast<float>(d01 - d00);
              const float bottom = static_cast<float>(d10) + fx * static_cast<float>(d11 - d10);
              const float v = top + fy * (bottom - top);
              if constexpr (std::is_same_v<T, uint16_t>) {
                value = static_cast<uint16_t>(v + 0.5f);  // v > 0: rounds to nearest
              } else {
                value = v;
              }
            }
          }
        }
      }
      out[i] = value;
    }
  }
};

Rectifier::Rectifier(const msgs::CameraInfo& info, const RectifyOptions& options,
                     std::string_view source)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.calibration = info;
  m.options = options;
  m.source = Str(source);
  m.rectified = RectifiedCameraInfo(info, options, source);
  // OpenCV's fixed-point maps and the int16 depth maps address at most 32767 pixels per axis.
  if (info.width > 32767 || info.height > 32767) {
    throw RectifyError(m.source + ": image size " + Size(info.width, info.height) +
                       " is larger than 32767 pixels per side");
  }
  m.passthrough = !HasDistortion(info) && m.rectified.fx == info.fx && m.rectified.fy == info.fy &&
                  m.rectified.cx == info.cx && m.rectified.cy == info.cy;
  const cv::Size size(static_cast<int>(info.width), static_cast<int>(info.height));
  const cv::Matx33d k_new(m.rectified.fx, 0, m.rectified.cx, 0, m.rectified.fy, m.rectified.cy, 0,
                          0, 1);
  std::vector<double> d = Coefficients(info);
  if (d.empty()) d.assign(5, 0.0);
  cv::initUndistortRectifyMap(CameraMatrix(info), d, cv::noArray(), k_new, size, CV_32FC1, m.map_x,
                              m.map_y);
  if (m.passthrough) return;
  cv::convertMaps(m.map_x, m.map_y, m.map_fixed, m.map_frac, CV_16SC2, false);
  const int w = size.width, h = size.height;
  const size_t n = static_cast<size_t>(w) * h;
  m.nearest.assign(n, {-1, -1});
  m.corner.assign(n, {-1, -1});
  m.fraction.assign(n, {0.f, 0.f});
  for (int y = 0; y < h; ++y) {
    const float* mx = m.map_x.ptr<float>(y);
    const float* my = m.map_y.ptr<float>(y);
    for (int x = 0; x < w; ++x) {
      const size_t i = static_cast<size_t>(y) * w + x;
      const float sx = mx[x], sy = my[x];
      if (!std::isfinite(sx) || !std::isfinite(sy)) continue;
      const long nx = std::lround(sx), ny = std::lround(sy);
      if (nx >= 0 && ny >= 0 && nx < w && ny < h) {
        m.nearest[i] = {static_cast<int16_t>(nx), static_cast<int16_t>(ny)};
      }
      const float fx0 = std::floor(sx), fy0 = std::floor(sy);
      if (fx0 >= 0 && fy0 >= 0 && fx0 + 1 < w && fy0 + 1 < h) {
        m.corner[i] = {static_cast<int16_t>(fx0), static_cast<int16_t>(fy0)};
        m.fraction[i] = {sx - fx0, sy - fy0};
      }
    }
  }
}

Rectifier::~Rectifier() = default;
Rectifier::Rectifier(Rectifier&&) noexcept = default;
Rectifier& Rectifier::operator=(Rectifier&&) noexcept = default;

bool Rectifier::Matches(const msgs::CameraInfo& info) const {
  const msgs::CameraInfo& c = impl_->calibration;
  if (info.width != c.width || info.height != c.height || info.fx != c.fx || info.fy != c.fy ||
      info.cx != c.cx || info.cy != c.cy) {
    return false;
  }
  // A model with only zero coefficients is the same camera as none.
  if (!HasDistortion(info) && !HasDistortion(c)) return true;
  if (info.distortion_model != c.distortion_model || info.distortion_count != c.distortion_count) {
    return false;
  }
  return std::equal(info.distortion, info.distortion + info.distortion_count, c.distortion);
}

const msgs::CameraInfo& Rectifier::rectified_info() const { return impl_->rectified; }

bool Rectifier::passthrough() const { return impl_->passthrough; }

std::array<float, 2> Rectifier::SourcePixel(uint32_t x, uint32_t y) const {
  Check(x < impl_->calibration.width && y < impl_->calibration.height, "SourcePixel out of range");
  return {impl_->map_x.at<float>(static_cast<int>(y), static_cast<int>(x)),
          impl_->map_y.at<float>(static_cast<int>(y), static_cast<int>(x))};
}

void CopyImage(const msgs::Image& in, std::span<const std::byte> in_pixels, msgs::Image& out,
               std::span<std::byte> out_pixels, std::string_view image_source) {
  const std::string name = Str(image_source);
  if (CvType(in.encoding) < 0) {
    throw RectifyError(name + ": invalid image encoding " +
                       std::to_string(static_cast<uint32_t>(in.encoding)));
  }
  PrepareOutput(in, in_pixels, out, out_pixels, name);
  CopyRows(in, in_pixels, out, out_pixels);
}

void Rectifier::Rectify(const msgs::Image& in, std::span<const std::byte> in_pixels,
                        msgs::Image& out, std::span<std::byte> out_pixels,
                        std::string_view image_source) const {
  const Impl& m = *impl_;
  const std::string name = Str(image_source);
  const int type = CvType(in.encoding);
  if (type < 0) {
    throw RectifyError(name + ": invalid image encoding " +
                       std::to_string(static_cast<uint32_t>(in.encoding)));
  }
  if (in.width != m.calibration.width || in.height != m.calibration.height) {
    throw RectifyError(name + ": image " + Size(in.width, in.height) +
                       " does not match the calibration (" +
                       Size(m.calibration.width, m.calibration.height) + " from " + m.source + ")");
  }
  PrepareOutput(in, in_pixels, out, out_pixels, name);
  const size_t row = out.step;
  if (m.passthrough) {
    CopyRows(in, in_pixels, out, out_pixels);
    return;
  }
  if (IsDepth(in.encoding)) {
    if (in.encoding == msgs::Encoding::kDepth16) {
      m.ResampleDepth<uint16_t>(in_pixels.data(), in.step, out_pixels.data());
    } else {
      m.ResampleDepth<float>(in_pixels.data(), in.step, out_pixels.data());
    }
    return;
  }
  const cv::Mat src(static_cast<int>(in.height), static_cast<int>(in.width), type,
                    const_cast<std::byte*>(in_pixels.data()), in.step);
  cv::Mat dst(static_cast<int>(in.height), static_cast<int>(in.width), type, out_pixels.data(),
              row);
  const void* target = dst.data;
  cv::remap(src, dst, m.map_fixed, m.map_frac, cv::INTER_LINEAR, cv::BORDER_CONSTANT,
            cv::Scalar::all(0));
  // remap must have written into the caller's buffer (the bus slot), not a new allocation.
  Check(dst.data == target, "remap reallocated its output");
}

}  // namespace probeless::rectify
