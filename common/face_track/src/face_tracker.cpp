#include "probeless/face_track/face_tracker.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/objdetect.hpp>
#include <opencv2/video/tracking.hpp>
#include <optional>

#include "dlib_landmarks.h"

namespace probeless::face_track {

using internal::Box;
using internal::GrayView;

DetectorBackend BackendFromName(const std::string& name) {
  if (name == "dlib") return DetectorBackend::kDlibHog;
  if (name == "yunet") return DetectorBackend::kYuNet;
  if (name == "haar") return DetectorBackend::kHaar;
  throw FaceTrackError("unknown face detector backend '" + name +
                       "' (expected dlib, yunet or haar)");
}

Intrinsics Intrinsics::Guess(int width, int height) {
  const double f = width / (2 * std::tan(M_PI / 6));
  return {f, f, (width - 1) / 2.0, (height - 1) / 2.0};
}

namespace {

// Box side / ((inter-ocular + eye-to-mouth) / 2) and centre position between the eye and mouth
// centres (0 = eyes, 1 = mouth), measured on dlib HOG boxes (see LandmarkBox).
constexpr double kBoxScale = 1.9;
constexpr double kBoxCentre = 0.5;

// The detector-style square box of a landmark set: centred between the eye centres and the mouth
// centre, side 1.9 x (inter-ocular + eye-to-mouth distance) / 2 (calibrated on dlib HOG boxes of
// the Yale B crops, so the shape predictor sees the boxes it was trained on).
Box LandmarkBox(const std::array<Point2f, kLandmarkCount>& p) {
  double ex[2] = {0, 0}, ey[2] = {0, 0}, mx = 0, my = 0;
  for (int i = 0; i < 6; ++i) {
    ex[0] += p[36 + i].x / 6;
    ey[0] += p[36 + i].y / 6;
    ex[1] += p[42 + i].x / 6;
    ey[1] += p[42 + i].y / 6;
  }
  for (int i = 48; i < 68; ++i) {
    mx += p[i].x / 20;
    my += p[i].y / 20;
  }
  const double cx = (ex[0] + ex[1]) / 2, cy = (ey[0] + ey[1]) / 2;
  const double iod = std::hypot(ex[1] - ex[0], ey[1] - ey[0]);
  const double em = std::hypot(mx - cx, my - cy);
  const double side = kBoxScale * (iod + em) / 2;
  const double bx = cx + kBoxCentre * (mx - cx), by = cy + kBoxCentre * (my - cy);
  return {bx - side / 2, by - side / 2, side, side, 0};
}

double InterOcular(const std::array<Point2f, kLandmarkCount>& p) {
  double ex[2] = {0, 0}, ey[2] = {0, 0};
  for (int i = 0; i < 6; ++i) {
    ex[0] += p[36 + i].x / 6;
    ey[0] += p[36 + i].y / 6;
    ex[1] += p[42 + i].x / 6;
    ey[1] += p[42 + i].y / 6;
  }
  return std::hypot(ex[1] - ex[0], ey[1] - ey[0]);
}

void CheckFile(const std::string& path, const std::string& what, const std::string& hint) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    throw FaceTrackError(what + " model '" + path + "' not found (" + hint + ")");
  }
}

}  // namespace

struct FaceTracker::Impl {
  TrackerOptions options;
  internal::DlibLandmarks landmarks;
  cv::Ptr<cv::FaceDetectorYN> yunet;
  cv::Ptr<cv::CLAHE> clahe;  // local contrast equalisation of the detector's image (or null)
  std::optional<cv::CascadeClassifier> haar;
  cv::Mat gray;      // the image the detector, the predictor and the flow see
  cv::Mat plain;     // this frame in gray (histogram-equalised if dark)
  cv::Mat contrast;  // plain with CLAHE applied to equalized_area
  cv::Mat padded, equalized_region;
  cv::Rect equalized_area;  // bounding box of the regions equalised in this frame
  cv::Rect track_region;    // tracking region (flow pyramids, CLAHE while tracking)
  cv::Mat converted;        // owned gray conversion of an RGB / BGR frame
  cv::Mat equalized;
  cv::Mat work;  // padded / scaled detection input
  cv::Mat bgr;   // YuNet input
  bool tracking = false;
  std::optional<Box> detection;  // this frame's successful detection (backend box)
  std::array<Point2f, kLandmarkCount> previous{};
  int64_t last_detection = 0;
  int64_t frames = 0, full = 0, region = 0;
  HeadPose raw_pose;
  PoseFilter filter;
  std::vector<cv::Mat> previous_pyramid;  // of the previous frame (flow)
  // Landmarks carried by the flow alone since the last detection (not reset to the shape
  // predictor's output, so its drift under changing shadows does not feed back).
  std::array<Point2f, kLandmarkCount> flow_landmarks{};

  explicit Impl(const TrackerOptions& o)
      : options(o), landmarks(o.shape_predictor_path), filter(o.pose_smoothing) {
    if (o.redetect_period < 1) throw FaceTrackError("redetect_period must be >= 1");
    if (o.detect_max_width < 160) throw FaceTrackError("detect_max_width must be >= 160");
    if (o.detect_min_size < 0 || o.detect_min_size > 4096) {
      throw FaceTrackError("detect_min_size must be in 0..4096");
    }
    if (!(o.max_scale_change > 1)) throw FaceTrackError("max_scale_change must be > 1");
    if (o.flow_min_points < 3 || o.flow_min_points > 51) {
      throw FaceTrackError("flow_min_points must be in 3..51");
    }
    if (!(o.flow_agreement > 0)) throw FaceTrackError("flow_agreement must be > 0");
    if (!(o.clahe_clip_limit >= 0)) throw FaceTrackError("clahe_clip_limit must be >= 0");
    if (o.clahe_clip_limit > 0) clahe = cv::createCLAHE(o.clahe_clip_limit, cv::Size(8, 8));
    if (o.max_undetected_frames < 1) throw FaceTrackError("max_undetected_frames must be >= 1");
    if (!(o.pose_smoothing >= 0 && o.pose_smoothing < 1)) {
      throw FaceTrackError("pose_smoothing must be in [0, 1)");
    }
    if (o.backend == DetectorBackend::kYuNet) {
      if (o.yunet_model_path.empty()) {
        throw FaceTrackError(
            "YuNet backend needs yunet_model_path (an ONNX face_detection_yunet "
            "model, e.g. ../shared/data/models/yunet_120x160.onnx)");
      }
      CheckFile(o.yunet_model_path, "YuNet", "set yunet_model_path to an ONNX YuNet model");
      try {
        yunet = cv::FaceDetectorYN::create(o.yunet_model_path, "", cv::Size(320, 320), 0.6f, 0.3f);
      } catch (const cv::Exception& e) {
        throw FaceTrackError("YuNet model '" + o.yunet_model_path + "' cannot be read");
      }
    } else if (o.backend == DetectorBackend::kHaar) {
      CheckFile(o.haar_cascade_path, "Haar cascade",
                "install the Debian package opencv-data, or set haar_cascade_path");
      haar.emplace();
      if (!haar->load(o.haar_cascade_path)) {
        throw FaceTrackError("Haar cascade model '" + o.haar_cascade_path + "' cannot be read");
      }
    }
  }

  // Mean gray (every 4th pixel of every 4th row) below 50.
  static bool Dark(const cv::Mat& m) {
    uint64_t sum = 0, n = 0;
    for (int y = 0; y < m.rows; y += 4) {
      const uint8_t* row = m.ptr<uint8_t>(y);
      for (int x = 0; x < m.cols; x += 4, ++n) sum += row[x];
    }
    return n > 0 && sum < 50 * n;
  }

  GrayView View(const cv::Mat& m) const {
    return {m.data, m.cols, m.rows, static_cast<size_t>(m.step)};
  }

  void ToGray(const ImageView& image) {
    if (!image.data || image.width <= 0 || image.height <= 0) {
      throw FaceTrackError("face tracker: empty image");
    }
    if (image.stride < static_cast<size_t>(image.width) * image.Channels()) {
      throw FaceTrackError("face tracker: stride " + std::to_string(image.stride) +
                           " is smaller than a row of " + std::to_string(image.width) + " pixels");
    }
    const cv::Mat in(image.height, image.width,
                     image.format == PixelFormat::kGray ? CV_8UC1 : CV_8UC3,
                     const_cast<uint8_t*>(image.data), image.stride);
    switch (image.format) {
      case PixelFormat::kGray:
        gray = in;  // no copy
        if (options.equalize && Dark(in)) {
          cv::equalizeHist(in, equalized);
          gray = equalized;
        }
        plain = gray;
        StartFrame();
        return;
      case PixelFormat::kRgb:
        cv::cvtColor(in, converted, cv::COLOR_RGB2GRAY);
        break;
      case PixelFormat::kBgr:
        cv::cvtColor(in, converted, cv::COLOR_BGR2GRAY);
        break;
    }
    if (options.equalize && Dark(converted)) cv::equalizeHist(converted, converted);
    gray = plain = converted;
    StartFrame();
  }

  // With CLAHE: `contrast` starts as a copy of the plain frame (regions are equalised on demand).
  void StartFrame() {
    equalized_area = cv::Rect();
    if (!clahe) return;
    plain.copyTo(contrast);
    gray = contrast;
  }

  // CLAHE (80 px tiles anchored at the image origin, tiles past the border reflected) of
  // `region` of the plain frame, snapped outward to the tile grid, into `contrast` (which holds
  // the plain frame elsewhere); the whole frame with the ~80 px tiles that divide it. Both grids
  // are the same when 80 divides the frame (640 x 480, 1280 x 720), so the tracked face's pixels
  // are equalised alike in every frame.
  void EqualizeRegion(const cv::Rect& region) {
    if (!clahe) return;
    constexpr int kTile = 80;
    const cv::Rect bounds(0, 0, plain.cols, plain.rows);
    const cv::Rect clipped = region & bounds;
    if (clipped.empty()) return;
    const int x0 = clipped.x / kTile * kTile, y0 = clipped.y / kTile * kTile;
    const int x1 = std::min(plain.cols, (clipped.br().x + kTile - 1) / kTile * kTile);
    const int y1 = std::min(plain.rows, (clipped.br().y + kTile - 1) / kTile * kTile);
    const cv::Rect snapped(x0, y0, x1 - x0, y1 - y0);
    if (snapped == bounds) {  // the whole frame: ~80 px tiles that divide it (2 x 2 on Yale B)
      clahe->setTilesGridSize(cv::Size(std::max(1, (plain.cols + kTile / 2) / kTile),
                                       std::max(1, (plain.rows + kTile / 2) / kTile)));
      clahe->apply(plain, contrast);
      equalized_area = bounds;
      return;
    }
    const int width = (snapped.width + kTile - 1) / kTile * kTile;
    const int height = (snapped.height + kTile - 1) / kTile * kTile;
    cv::Mat source = plain(snapped);
    if (width != snapped.width || height != snapped.height) {
      cv::copyMakeBorder(source, padded, 0, height - snapped.height, 0, width - snapped.width,
                         cv::BORDER_REFLECT_101);
      source = padded;
    }
    clahe->setTilesGridSize(cv::Size(width / kTile, height / kTile));
    clahe->apply(source, equalized_region);
    equalized_region(cv::Rect(0, 0, snapped.width, snapped.height)).copyTo(contrast(snapped));
    equalized_area |= snapped;
  }
  void EqualizeAll() { EqualizeRegion(cv::Rect(0, 0, plain.cols, plain.rows)); }

  // The tracking region for landmarks: three face boxes around them (covers the region
  // re-detection's two boxes and the flow's motion), snapped to the CLAHE tile grid.
  cv::Rect TrackingRegion(const std::array<Point2f, kLandmarkCount>& lms) const {
    const Box b = LandmarkBox(lms);
    const double cx = b.x + b.width / 2, cy = b.y + b.height / 2, half = 1.5 * b.width;
    cv::Rect r(static_cast<int>(std::floor(cx - half)), static_cast<int>(std::floor(cy - half)),
               static_cast<int>(std::ceil(2 * half)), static_cast<int>(std::ceil(2 * half)));
    r &= cv::Rect(0, 0, plain.cols, plain.rows);
    constexpr int kTile = 80;
    const int x0 = r.x / kTile * kTile, y0 = r.y / kTile * kTile;
    const int x1 = std::min(plain.cols, (r.br().x + kTile - 1) / kTile * kTile);
    const int y1 = std::min(plain.rows, (r.br().y + kTile - 1) / kTile * kTile);
    return cv::Rect(x0, y0, std::max(0, x1 - x0), std::max(0, y1 - y0));
  }

  // Backend detections on `input` (already padded / scaled), in its pixels.
  std::vector<Box> RunDetector(const cv::Mat& input) {
    std::vector<Box> boxes;
    switch (options.backend) {
      case DetectorBackend::kDlibHog:
        return landmarks.Detect(View(input));
      case DetectorBackend::kYuNet: {
        cv::cvtColor(input, bgr, cv::COLOR_GRAY2BGR);
        yunet->setInputSize(input.size());
        cv::Mat faces;
        yunet->detect(bgr, faces);
        for (int i = 0; i < faces.rows; ++i) {
          const float* f = faces.ptr<float>(i);
          boxes.push_back({f[0], f[1], f[2], f[3], f[14]});
        }
        break;
      }
      case DetectorBackend::kHaar: {
        std::vector<cv::Rect> found;
        haar->detectMultiScale(input, found, 1.1, 4, 0, cv::Size(40, 40));
        for (const auto& r : found) {
          boxes.push_back(
              {double(r.x), double(r.y), double(r.width), double(r.height), double(r.area())});
        }
        break;
      }
    }
    std::stable_sort(boxes.begin(), boxes.end(),
                     [](const Box& a, const Box& b) { return a.score > b.score; });
    return boxes;
  }

  // Detection in `roi` of the gray image, scaled so that it is at most max_width wide and padded
  // to detect_min_size; boxes in image pixels.
  std::vector<Box> DetectIn(const cv::Rect& roi, int max_width) {
    cv::Mat src = gray(roi);
    double scale = 1;
    if (src.cols > max_width) {
      scale = static_cast<double>(max_width) / src.cols;
      cv::resize(src, work, cv::Size(), scale, scale, cv::INTER_AREA);
    } else {
      work = src;
    }
    const int min_size = options.detect_min_size;
    int pad_x = 0, pad_y = 0;
    if (work.cols < min_size || work.rows < min_size) {
      pad_x = std::max(0, (min_size - work.cols + 1) / 2);
      pad_y = std::max(0, (min_size - work.rows + 1) / 2);
      cv::Mat padded;
      cv::copyMakeBorder(work, padded, pad_y, pad_y, pad_x, pad_x, cv::BORDER_CONSTANT,
                         cv::mean(work));
      work = padded;
    }
    std::vector<Box> boxes = RunDetector(work);
    for (Box& b : boxes) {
      b.x = (b.x - pad_x) / scale + roi.x;
      b.y = (b.y - pad_y) / scale + roi.y;
      b.width /= scale;
      b.height /= scale;
    }
    return boxes;
  }

  std::optional<Box> DetectFull() {
    const auto boxes = DetectIn(cv::Rect(0, 0, gray.cols, gray.rows), options.detect_max_width);
    if (boxes.empty()) return std::nullopt;
    return boxes.front();
  }

  // Detection in a region twice the tracked face box, scaled so the face is ~120 px wide; the
  // detection overlapping the tracked box most.
  std::optional<Box> DetectRegion(const Box& box) {
    const double cx = box.x + box.width / 2, cy = box.y + box.height / 2;
    const double half = box.width;  // region side = 2 x box
    cv::Rect roi(static_cast<int>(std::floor(cx - half)), static_cast<int>(std::floor(cy - half)),
                 static_cast<int>(std::ceil(2 * half)), static_cast<int>(std::ceil(2 * half)));
    roi &= cv::Rect(0, 0, gray.cols, gray.rows);
    if (roi.width < 8 || roi.height < 8) return std::nullopt;
    const int max_width = std::max(160, static_cast<int>(roi.width * 120.0 / box.width));
    const auto boxes = DetectIn(roi, max_width);
    std::optional<Box> best;
    double best_overlap = 0.3;
    for (const Box& b : boxes) {
      const double ix =
          std::max(0.0, std::min(b.x + b.width, box.x + box.width) - std::max(b.x, box.x));
      const double iy =
          std::max(0.0, std::min(b.y + b.height, box.y + box.height) - std::max(b.y, box.y));
      const double inter = ix * iy;
      const double iou = inter / (b.width * b.height + box.width * box.height - inter);
      if (iou > best_overlap) {
        best_overlap = iou;
        best = b;
      }
    }
    return best;
  }

  std::array<Point2f, kLandmarkCount> FromDetection(const Box& box) {
    detection = box;
    const auto first = landmarks.Landmarks(View(gray), box);
    return landmarks.Landmarks(View(gray), LandmarkBox(first));
  }

  // Follows the inner landmarks (17..67) of flow_landmarks from the previous frame to gray
  // (pyramidal Lucas-Kanade, 21 x 21 window, 3 levels; a point counts if its forward-backward error
  // is below 1 px + 2 % of the inter-ocular distance), fits a similarity to them (RANSAC, 3 % of
  // the inter-ocular distance) and returns flow_landmarks moved by it and the number of inliers (0
  // if the flow failed).
  int Flow(std::array<Point2f, kLandmarkCount>& moved) {
    constexpr int kFirst = 17;
    if (previous_pyramid.empty() || track_region.empty()) return 0;
    const double iod = InterOcular(flow_landmarks);
    // Both pyramids are of `region` (pixels relative to its corner).
    const cv::Point2f origin(static_cast<float>(track_region.x),
                             static_cast<float>(track_region.y));
    std::vector<cv::Point2f> from, to, back;
    for (int i = kFirst; i < kLandmarkCount; ++i) {
      from.emplace_back(cv::Point2f(flow_landmarks[i].x, flow_landmarks[i].y) - origin);
    }
    std::vector<cv::Mat> pyramid;
    const cv::Size window(21, 21);
    // Level 0 copied (tryReuseInputImage false): the pyramid outlives `gray`, which the next
    // frame overwrites.
    cv::buildOpticalFlowPyramid(gray(track_region), pyramid, window, 3, false,
                                cv::BORDER_REFLECT_101, cv::BORDER_CONSTANT, false);
    std::vector<uint8_t> status, status_back;
    std::vector<float> error;
    const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 0.03);
    cv::calcOpticalFlowPyrLK(previous_pyramid, pyramid, from, to, status, error, window, 3,
                             criteria);
    cv::calcOpticalFlowPyrLK(pyramid, previous_pyramid, to, back, status_back, error, window, 3,
                             criteria);
    std::vector<cv::Point2f> good_from, good_to;
    const double max_fb = 1.0 + 0.02 * iod;
    for (size_t i = 0; i < from.size(); ++i) {
      if (!status[i] || !status_back[i]) continue;
      if (std::hypot(back[i].x - from[i].x, back[i].y - from[i].y) > max_fb) continue;
      good_from.push_back(from[i]);
      good_to.push_back(to[i]);
    }
    previous_pyramid = std::move(pyramid);
    if (static_cast<int>(good_from.size()) < options.flow_min_points) return 0;
    std::vector<uint8_t> inliers;
    const cv::Mat similarity = cv::estimateAffinePartial2D(
        good_from, good_to, inliers, cv::RANSAC, std::max(1.0, 0.03 * iod), 200, 0.99, 10);
    if (similarity.empty()) return 0;
    int count = 0;
    for (uint8_t v : inliers) count += v != 0;
    const double* m = similarity.ptr<double>(0);
    for (int i = 0; i < kLandmarkCount; ++i) {
      const double x = flow_landmarks[i].x - origin.x, y = flow_landmarks[i].y - origin.y;
      moved[i] = {static_cast<float>(m[0] * x + m[1] * y + m[2] + origin.x),
                  static_cast<float>(m[3] * x + m[4] * y + m[5] + origin.y)};
    }
    return count;
  }

  // After a frame with a face: moves the tracking region if the face left it (equalising it in
  // this frame) and keeps this frame's pyramid of the region for the next Flow unless Flow has
  // (same region).
  void UpdateRegion(const std::array<Point2f, kLandmarkCount>& lms, bool have_pyramid) {
    const cv::Rect needed = TrackingRegion(lms);
    if ((needed & track_region) != needed || track_region.empty()) {
      track_region = needed;
      have_pyramid = false;
      if ((track_region & equalized_area) != track_region) EqualizeRegion(track_region);
    }
    if (!options.flow_tracking || have_pyramid || track_region.empty()) return;
    cv::buildOpticalFlowPyramid(gray(track_region), previous_pyramid, cv::Size(21, 21), 3, false,
                                cv::BORDER_REFLECT_101, cv::BORDER_CONSTANT, false);
  }

  FaceTrack Finish(const std::array<Point2f, kLandmarkCount>& lms, bool detected,
                   const Intrinsics& k, bool filtered) {
    FaceTrack t;
    t.found = true;
    t.detected = detected;
    t.confidence = detected ? 1.0f : 0.0f;
    t.landmarks = lms;
    const Box b = LandmarkBox(lms);
    t.box = {float(b.x), float(b.y), float(b.width), float(b.height)};
    if (detected && detection) {
      t.detection_box = {float(detection->x), float(detection->y), float(detection->width),
                         float(detection->height)};
    }
    const Intrinsics in = k.fx > 0 ? k : Intrinsics::Guess(gray.cols, gray.rows);
    HeadPose measured = EstimateHeadPose(lms, in.fx, in.fy, in.cx, in.cy,
                                         filtered ? raw_pose : HeadPose{}, &t.pose_rms_px);
    if (filtered) {
      raw_pose = measured;
      t.pose = filter.Update(measured);
    } else {
      t.pose = measured;
    }
    return t;
  }
};

FaceTracker::FaceTracker(const TrackerOptions& options) : impl_(std::make_unique<Impl>(options)) {}
FaceTracker::~FaceTracker() = default;

const TrackerOptions& FaceTracker::options() const { return impl_->options; }
int64_t FaceTracker::frames() const { return impl_->frames; }
int64_t FaceTracker::full_detections() const { return impl_->full; }
int64_t FaceTracker::region_detections() const { return impl_->region; }

void FaceTracker::Reset() {
  impl_->tracking = false;
  impl_->raw_pose = {};
  impl_->filter.Reset();
}

FaceTrack FaceTracker::Track(const ImageView& image, const Intrinsics& intrinsics) {
  Impl& s = *impl_;
  s.ToGray(image);
  s.detection.reset();
  ++s.frames;
  bool detected = false, flow_only = false, flowed = false;
  double confidence = 1;
  std::array<Point2f, kLandmarkCount> lms{};
  if (s.tracking) s.EqualizeRegion(s.track_region);
  if (s.tracking && s.options.flow_tracking) {
    // Flow first: it moves the flow landmarks to this frame.
    std::array<Point2f, kLandmarkCount> moved{};
    const int inliers = s.Flow(moved);
    const bool flow_ok = inliers >= s.options.flow_min_points;
    const Box box = LandmarkBox(flow_ok ? moved : s.previous);
    flowed = inliers > 0 || !s.previous_pyramid.empty();
    bool redetected = false, redetect_failed = false;
    if (s.frames - s.last_detection >= s.options.redetect_period) {
      ++s.region;
      if (auto found = s.DetectRegion(box)) {
        lms = s.FromDetection(*found);
        detected = redetected = true;
        s.last_detection = s.frames;
      } else {
        redetect_failed = true;
      }
    }
    if (!redetected) {
      if ((!flow_ok && redetect_failed) ||
          s.frames - s.last_detection > s.options.max_undetected_frames) {
        s.tracking = false;
      } else if (!flow_ok) {
        // No flow (e.g. unrelated frames such as a Yale B sequence): landmarks in the previous
        // box as without flow tracking, unverified, and the flow restarts from them.
        lms = s.landmarks.Landmarks(s.View(s.gray), box);
        s.flow_landmarks = lms;
        confidence = 0.5;
      } else {
        s.flow_landmarks = moved;
        lms = s.landmarks.Landmarks(s.View(s.gray), box);
        std::vector<double> distances;
        for (int i = 17; i < kLandmarkCount; ++i) {
          distances.push_back(std::hypot(lms[i].x - moved[i].x, lms[i].y - moved[i].y));
        }
        std::nth_element(distances.begin(), distances.begin() + distances.size() / 2,
                         distances.end());
        const double agreement = distances[distances.size() / 2] / InterOcular(moved);
        confidence = static_cast<double>(inliers) / (kLandmarkCount - 17);
        if (!(agreement < s.options.flow_agreement)) {
          lms = moved;  // the predictor lost the half-lit face: keep the flow's landmarks
          flow_only = true;
          confidence *= 0.5;
        }
      }
    }
    if (s.tracking) {
      const double ratio = InterOcular(lms) / std::max(1e-6, InterOcular(s.previous));
      if (!(ratio < s.options.max_scale_change && ratio > 1 / s.options.max_scale_change)) {
        s.tracking = false;
      }
    }
  } else if (s.tracking) {
    const Box previous_box = LandmarkBox(s.previous);
    if (s.frames - s.last_detection >= s.options.redetect_period) {
      ++s.region;
      if (auto box = s.DetectRegion(previous_box)) {
        lms = s.FromDetection(*box);
        detected = true;
        s.last_detection = s.frames;
      } else {
        s.tracking = false;
      }
    } else {
      lms = s.landmarks.Landmarks(s.View(s.gray), previous_box);
    }
    if (s.tracking) {
      const double ratio = InterOcular(lms) / std::max(1e-6, InterOcular(s.previous));
      if (!(ratio < s.options.max_scale_change && ratio > 1 / s.options.max_scale_change)) {
        s.tracking = false;
      }
    }
  }
  if (!s.tracking) {
    s.EqualizeAll();
    s.track_region = cv::Rect();
    s.raw_pose = {};
    s.filter.Reset();
    ++s.full;
    const auto box = s.DetectFull();
    if (!box) return {};
    lms = s.FromDetection(*box);
    detected = true;
    flow_only = false;
    confidence = 1;
    s.tracking = true;
    s.last_detection = s.frames;
  }
  s.previous = lms;
  if (detected) s.flow_landmarks = lms;
  s.UpdateRegion(lms, flowed && s.tracking);
  FaceTrack t = s.Finish(lms, detected, intrinsics, true);
  t.flow = flow_only;
  t.confidence = static_cast<float>(detected ? 1.0 : confidence);
  return t;
}

FaceTrack FaceTracker::DetectOnce(const ImageView& image, const Intrinsics& intrinsics) {
  Impl& s = *impl_;
  s.ToGray(image);
  s.detection.reset();
  s.EqualizeAll();
  const auto box = s.DetectFull();
  if (!box) return {};
  return s.Finish(s.FromDetection(*box), true, intrinsics, false);
}

}  // namespace probeless::face_track
