#include "probeless/capture/capture_node.h"

#include <time.h>

#include <cmath>
#include <cstring>
#include <thread>

#include "probeless/capture/capture_error.h"
#include "probeless/msgs/camera_info.h"
#include "probeless/msgs/image.h"

namespace probeless::capture {

int64_t MonotonicNowNs() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);
  return static_cast<int64_t>(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
}

int64_t RealtimeNowNs() {
  timespec t{};
  clock_gettime(CLOCK_REALTIME, &t);
  return static_cast<int64_t>(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
}

int64_t RealtimeFromMonotonic(int64_t mono_ns) {
  const int64_t mono = MonotonicNowNs();
  const int64_t wall = RealtimeNowNs();
  return mono_ns + (wall - mono);
}

int64_t DeviceClock::ToMonotonic(int64_t device_ns, int64_t arrival_mono_ns) {
  const int64_t offset = arrival_mono_ns - device_ns;
  // A device clock that jumps back (reset, looped recording) restarts the estimate.
  if (count_ == 0 || device_ns < last_device_ns_ || count_ >= window_) {
    if (count_ == 0 || device_ns < last_device_ns_) {
      offset_ = offset;
    } else {
      // Let the estimate follow drift: forget the minimum slowly.
      offset_ = std::min(offset, offset_ + (offset - offset_) / 8);
    }
    count_ = 1;
  } else {
    offset_ = std::min(offset_, offset);
    ++count_;
  }
  last_device_ns_ = device_ns;
  return device_ns + offset_ - latency_ns_;
}

// --- FramePublisher
// -------------------------------------------------------------------------------

FramePublisher::FramePublisher(bus::Publisher* image, bus::Publisher* depth,
                               bus::Publisher* camera_info, const Intrinsics& intrinsics,
                               double depth_scale, const std::string& frame_id)
    : image_(image),
      depth_(depth),
      camera_info_(camera_info),
      intrinsics_(intrinsics),
      depth_scale_(depth_scale),
      frame_id_(frame_id) {}

void FramePublisher::PublishImage(bus::Publisher& publisher, const RawFrame& frame,
                                  uint64_t sequence) {
  const size_t bytes =
      msgs::Image::MessageBytesFor(frame.width, frame.height, OutputEncoding(frame.format));
  bus::Loan loan = publisher.Borrow(bytes);
  msgs::WriteView<msgs::Image> out = msgs::WriteMessage<msgs::Image>(loan.data());
  ConvertFrame(frame, *out, out.payload);  // straight into the slot
  out->header.stamp_mono_ns = frame.stamp_mono_ns;
  out->header.stamp_ns = RealtimeFromMonotonic(frame.stamp_mono_ns);
  out->header.sequence = sequence;
  out->header.SetFrameId(frame_id_);
  publisher.Publish(std::move(loan));
}

void FramePublisher::PublishInfo(int64_t stamp_mono_ns, uint64_t sequence) {
  if (camera_info_ == nullptr) return;
  bus::Loan loan = camera_info_->Borrow(sizeof(msgs::CameraInfo));
  msgs::WriteView<msgs::CameraInfo> out = msgs::WriteMessage<msgs::CameraInfo>(loan.data());
  calib::FillCameraInfo(intrinsics_, depth_scale_, *out);
  out->header.stamp_mono_ns = stamp_mono_ns;
  out->header.stamp_ns = RealtimeFromMonotonic(stamp_mono_ns);
  out->header.sequence = sequence;
  out->header.SetFrameId(frame_id_);
  camera_info_->Publish(std::move(loan));
}

void FramePublisher::Publish(const FrameSet& frames) {
  // Counted once published: a frame that does not convert (dropped by the loop) takes no
  // sequence number and is not reported as published.
  if (frames.depth && depth_ != nullptr) {
    PublishImage(*depth_, *frames.depth, depth_count_ + 1);
    ++depth_count_;
  }
  if (frames.colour && image_ != nullptr) {
    PublishImage(*image_, *frames.colour, colour_count_ + 1);
    ++colour_count_;
    PublishInfo(frames.colour->stamp_mono_ns, colour_count_);
  } else if (frames.depth && image_ == nullptr) {
    PublishInfo(frames.depth->stamp_mono_ns, depth_count_);
  }
}

// --- RunCaptureNode
// -------------------------------------------------------------------------------

namespace {

// Consecutive frames that cannot be converted before the node gives up (1 s at 30 fps): a single
// corrupt frame is dropped, a camera that sends nothing usable is an error.
constexpr int kMaxCorruptFramesInARow = 30;

struct Settings {
  std::string frame_id;
  std::string camera_info_url;
  double default_fov_deg = 60;
  bool retry = false;
  double retry_period_s = 1;
  double stall_timeout_s = 1;
  uint64_t max_frames = 0;
  uint32_t slots = 8;
};

size_t MessageBytes(const std::optional<StreamInfo>& stream) {
  if (!stream) return 0;
  return msgs::Image::MessageBytesFor(stream->width, stream->height,
                                      OutputEncoding(stream->format));
}

}  // namespace

int RunCaptureNode(node::Node& node, const DeviceOpener& open) {
  Settings s;
  s.frame_id = node.Param("frame_id", "camera");
  s.camera_info_url = node.Param("camera_info_url", "");
  if (s.camera_info_url.starts_with("file://")) s.camera_info_url = s.camera_info_url.substr(7);
  s.default_fov_deg = node.Param("default_fov_deg", 60.0);
  s.retry = node.Param("retry", false);
  s.retry_period_s = node.Param("retry_period_s", 1.0);
  s.stall_timeout_s = node.Param("stall_timeout_s", 1.0);
  s.max_frames = static_cast<uint64_t>(node.Param<int64_t>("max_frames", 0));
  s.slots = static_cast<uint32_t>(node.Param<int64_t>("slots", 8));
  node.CheckParamOverrides();

  std::unique_ptr<bus::Publisher> image;
  std::unique_ptr<bus::Publisher> depth;
  std::unique_ptr<bus::Publisher> camera_info;
  size_t image_capacity = 0;
  size_t depth_capacity = 0;
  uint64_t frames_total = 0;
  uint64_t corrupt_total = 0;  // frames dropped because they could not be converted
  bool waiting_logged = false;
  const auto stall = std::chrono::nanoseconds(static_cast<int64_t>(s.stall_timeout_s * 1e9));

  while (node.ok()) {
    std::unique_ptr<Device> device;
    try {
      device = open();
    } catch (const CaptureError& e) {
      if (!s.retry || !e.retryable()) {
        node.Error() << e.what()
                     << (e.retryable() ? " (set param retry: true to wait for it)" : "");
        return 1;
      }
      if (!waiting_logged) {
        node.Warn() << e.what() << " (retrying every " << s.retry_period_s << " s)";
        waiting_logged = true;
      }
      if (node.WaitForShutdown(
              std::chrono::nanoseconds(static_cast<int64_t>(s.retry_period_s * 1e9)))) {
        break;
      }
      continue;
    }
    waiting_logged = false;
    const std::optional<StreamInfo> colour = device->colour_stream();
    const std::optional<StreamInfo> depth_stream = device->depth_stream();
    // Publishers are created once and kept across reopen (subscribers stay connected); a larger
    // frame than before needs a new pool.
    if (colour && (!image || MessageBytes(colour) > image_capacity)) {
      image_capacity = MessageBytes(colour);
      image.reset();
      image = std::make_unique<bus::Publisher>(node.CreatePublisher<msgs::Image>(
          "camera/image", {.max_message_bytes = image_capacity, .slot_count = s.slots}));
    }
    if (depth_stream && (!depth || MessageBytes(depth_stream) > depth_capacity)) {
      depth_capacity = MessageBytes(depth_stream);
      depth.reset();
      depth = std::make_unique<bus::Publisher>(node.CreatePublisher<msgs::Image>(
          "camera/depth", {.max_message_bytes = depth_capacity, .slot_count = s.slots}));
    }
    if (!camera_info) {
      camera_info = std::make_unique<bus::Publisher>(
          node.CreatePublisher<msgs::CameraInfo>("camera/camera_info", {.slot_count = s.slots}));
    }
    const StreamInfo& main = colour ? *colour : *depth_stream;
    ResolvedIntrinsics intrinsics;
    try {
      intrinsics = ResolveIntrinsics(s.camera_info_url, device->factory_intrinsics(), main.width,
                                     main.height, s.default_fov_deg);
    } catch (const CaptureError& e) {
      node.Error() << e.what();
      return 1;
    }
    if (intrinsics.calibrated) {
      node.Info() << "intrinsics from " << intrinsics.source;
    } else {
      node.Warn() << "intrinsics " << intrinsics.source;
    }
    std::string streams;
    if (colour) {
      streams += "image " + std::to_string(colour->width) + "x" + std::to_string(colour->height) +
                 " " + std::string(PixelFormatName(colour->format));
    }
    if (depth_stream) {
      streams += std::string(streams.empty() ? "" : ", ") + "depth " +
                 std::to_string(depth_stream->width) + "x" + std::to_string(depth_stream->height) +
                 (device->depth_registered() ? " (registered to colour)" : " (NOT registered)");
    }
    node.Info() << "streaming from " << device->description() << ": " << streams;
    FramePublisher publisher(colour ? image.get() : nullptr, depth_stream ? depth.get() : nullptr,
                             camera_info.get(), intrinsics.intrinsics, depth_stream ? 0.001 : 0.0,
                             s.frame_id);
    auto last_frame = std::chrono::steady_clock::now();
    int corrupt_in_a_row = 0;
    try {
      FrameSet frames;
      while (node.ok()) {
        frames = {};
        if (!device->Next(std::chrono::milliseconds(50), frames)) {
          if (std::chrono::steady_clock::now() - last_frame > stall) {
            throw CaptureError(ErrorKind::kDisconnected,
                               device->description() + " delivered no frame for " +
                                   std::to_string(s.stall_timeout_s).substr(0, 4) +
                                   " s: check the cable and USB bandwidth, or replug it");
          }
          continue;
        }
        last_frame = std::chrono::steady_clock::now();
        try {
          publisher.Publish(frames);
          corrupt_in_a_row = 0;
        } catch (const CaptureError& e) {
          // One corrupt frame (a truncated MJPEG) is dropped; a stream of them is a broken or
          // misconfigured camera and ends the node as before.
          if (e.kind() != ErrorKind::kBadInput) throw;
          if (++corrupt_in_a_row >= kMaxCorruptFramesInARow) {
            throw CaptureError(ErrorKind::kBadInput,
                               device->description() + ": " +
                                   std::to_string(kMaxCorruptFramesInARow) +
                                   " frames in a row cannot be converted (" + e.what() +
                                   "): check pixel_format, or the camera and its cable");
          }
          ++corrupt_total;
          if (corrupt_total <= 10 || corrupt_total % 100 == 0) {
            node.Warn() << "dropped a frame that cannot be converted (" << corrupt_total
                        << " so far): " << e.what();
          }
          continue;
        }
        ++frames_total;
        if (s.max_frames != 0 && frames_total >= s.max_frames) {
          node.Info() << "published " << publisher.published_colour() << " images and "
                      << publisher.published_depth() << " depth images (max_frames reached)";
          return 0;
        }
      }
    } catch (const CaptureError& e) {
      device.reset();
      node.Info() << "published " << publisher.published_colour() << " images and "
                  << publisher.published_depth() << " depth images";
      if (!s.retry || !e.retryable()) {
        node.Error() << e.what()
                     << (e.retryable() ? " (set param retry: true to wait for it)" : "");
        return 1;
      }
      node.Warn() << e.what() << " (waiting for it to come back)";
      continue;
    }
  }
  return 0;
}

}  // namespace probeless::capture
