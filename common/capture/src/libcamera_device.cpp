// libcamera backend (0.0.3 API). libcamera headers stay in this file.
#include <libcamera/libcamera.h>
#include <sys/mman.h>

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <mutex>

#include "probeless/capture/capture_error.h"
#include "probeless/capture/v4l2.h"

namespace probeless::capture {

namespace {

using namespace libcamera;

std::optional<PixelFormat> FromLibcamera(const libcamera::PixelFormat& f) {
  // libcamera names formats after DRM: RGB888 is B, G, R in memory; BGR888 is R, G, B.
  if (f == formats::RGB888) return PixelFormat::kBgr24;
  if (f == formats::BGR888) return PixelFormat::kRgb24;
  if (f == formats::YUYV) return PixelFormat::kYuyv;
  if (f == formats::MJPEG) return PixelFormat::kMjpeg;
  if (f == formats::R8) return PixelFormat::kGrey;
  return std::nullopt;
}

std::vector<libcamera::PixelFormat> Candidates(const std::string& name) {
  if (name == "auto") {
    return {formats::BGR888, formats::RGB888, formats::YUYV, formats::MJPEG, formats::R8};
  }
  switch (PixelFormatFromName(name)) {
    case PixelFormat::kRgb24:
      return {formats::BGR888};
    case PixelFormat::kBgr24:
      return {formats::RGB888};
    case PixelFormat::kYuyv:
      return {formats::YUYV};
    case PixelFormat::kMjpeg:
      return {formats::MJPEG};
    case PixelFormat::kGrey:
      return {formats::R8};
    default:
      return {};
  }
}

class CameraManagerHandle {
 public:
  CameraManagerHandle() : manager_(std::make_unique<CameraManager>()) {
    const int rc = manager_->start();
    if (rc < 0) {
      throw CaptureError(ErrorKind::kDeviceError,
                         "libcamera camera manager does not start (error " + std::to_string(rc) +
                             "): check /dev/media* access");
    }
  }
  ~CameraManagerHandle() { manager_->stop(); }
  CameraManager& get() { return *manager_; }

 private:
  std::unique_ptr<CameraManager> manager_;
};

class LibcameraDevice final : public Device {
 public:
  LibcameraDevice(const LibcameraOptions& options,
                  const std::function<void(const std::string&)>& log) {
    std::vector<std::shared_ptr<Camera>> cameras = manager_.get().cameras();
    std::string ids;
    for (const auto& c : cameras) ids += std::string(ids.empty() ? "" : ", ") + c->id();
    for (const auto& c : cameras) {
      if (options.camera_id.empty() || c->id() == options.camera_id ||
          c->id().find(options.camera_id) != std::string::npos) {
        camera_ = c;
        break;
      }
    }
    description_ = "libcamera camera '" + (camera_ ? camera_->id() : options.camera_id) + "'";
    if (!camera_) {
      throw CaptureError(
          ErrorKind::kNoDevice,
          description_ + " not found (" +
              (ids.empty() ? std::string("libcamera finds no camera") : "found: " + ids) +
              "): connect it, or set param camera_id (cam --list)");
    }
    const int acquired = camera_->acquire();
    if (acquired == -EBUSY) {
      throw CaptureError(ErrorKind::kBusy, description_ + " is in use by another process");
    }
    if (acquired < 0) {
      throw CaptureError(ErrorKind::kDeviceError, description_ + " cannot be acquired (error " +
                                                      std::to_string(acquired) + ")");
    }
    acquired_ = true;
    config_ = camera_->generateConfiguration({StreamRole::VideoRecording});
    if (!config_ || config_->empty()) {
      throw CaptureError(ErrorKind::kBadInput, description_ + " has no video stream");
    }
    StreamConfiguration& sc = config_->at(0);
    std::optional<PixelFormat> chosen;
    std::string offered;
    for (const libcamera::PixelFormat& f : sc.formats().pixelformats()) {
      offered += std::string(offered.empty() ? "" : ", ") + f.toString();
    }
    for (const libcamera::PixelFormat& candidate : Candidates(options.pixel_format)) {
      const auto& supported = sc.formats().pixelformats();
      if (std::find(supported.begin(), supported.end(), candidate) == supported.end()) continue;
      sc.pixelFormat = candidate;
      chosen = FromLibcamera(candidate);
      break;
    }
    if (!chosen) {
      throw CaptureError(ErrorKind::kBadInput, description_ + " offers no " + options.pixel_format +
                                                   " format (offers: " + offered +
                                                   "): set param pixel_format");
    }
    sc.size = Size(options.width, options.height);
    sc.bufferCount = std::max<uint32_t>(2, options.buffers);
    if (config_->validate() == CameraConfiguration::Invalid) {
      throw CaptureError(ErrorKind::kBadInput, description_ + " rejects " +
                                                   std::to_string(options.width) + "x" +
                                                   std::to_string(options.height));
    }
    chosen = FromLibcamera(sc.pixelFormat);
    if (!chosen) {
      throw CaptureError(
          ErrorKind::kBadInput,
          description_ + " adjusted the format to unsupported " + sc.pixelFormat.toString());
    }
    if (camera_->configure(config_.get()) < 0) {
      throw CaptureError(ErrorKind::kDeviceError, description_ + " cannot be configured");
    }
    stream_info_ = StreamInfo{*chosen, sc.size.width, sc.size.height, 0};
    stride_ = *chosen == PixelFormat::kMjpeg ? 0 : sc.stride;
    stream_ = sc.stream();
    allocator_ = std::make_unique<FrameBufferAllocator>(camera_);
    if (allocator_->allocate(stream_) < 0) {
      throw CaptureError(ErrorKind::kDeviceError, description_ + " cannot allocate buffers");
    }
    for (const std::unique_ptr<FrameBuffer>& buffer : allocator_->buffers(stream_)) {
      std::unique_ptr<Request> request = camera_->createRequest();
      if (!request || request->addBuffer(stream_, buffer.get()) < 0) {
        throw CaptureError(ErrorKind::kDeviceError, description_ + " cannot create requests");
      }
      const FrameBuffer::Plane& plane = buffer->planes().front();
      void* p =
          mmap(nullptr, plane.offset + plane.length, PROT_READ, MAP_SHARED, plane.fd.get(), 0);
      if (p == MAP_FAILED) {
        throw CaptureError(ErrorKind::kDeviceError, description_ + " cannot map its buffers");
      }
      maps_[buffer.get()] = {static_cast<uint8_t*>(p), plane.offset, plane.length};
      requests_.push_back(std::move(request));
    }
    camera_->requestCompleted.connect(this, &LibcameraDevice::OnCompleted);
    ControlList controls(camera_->controls());
    const ControlInfoMap& info = camera_->controls();
    auto supported = [&](const ControlId& id) { return info.find(&id) != info.end(); };
    const bool manual = options.exposure_time_us.has_value() || options.analogue_gain.has_value();
    if ((options.auto_exposure || manual) && supported(controls::AeEnable)) {
      controls.set(controls::AeEnable, options.auto_exposure.value_or(false) && !manual);
    }
    if (options.exposure_time_us) {
      if (supported(controls::ExposureTime)) {
        controls.set(controls::ExposureTime, static_cast<int32_t>(*options.exposure_time_us));
      } else {
        log(description_ + ": no ExposureTime control; exposure_time_us ignored");
      }
    }
    if (options.analogue_gain) {
      if (supported(controls::AnalogueGain)) {
        controls.set(controls::AnalogueGain, static_cast<float>(*options.analogue_gain));
      } else {
        log(description_ + ": no AnalogueGain control; analogue_gain ignored");
      }
    }
    if (options.auto_white_balance) {
      if (supported(controls::AwbEnable)) {
        controls.set(controls::AwbEnable, *options.auto_white_balance);
      } else {
        log(description_ + ": no AwbEnable control; auto_white_balance ignored");
      }
    }
    if (camera_->start(&controls) < 0) {
      throw CaptureError(ErrorKind::kDeviceError, description_ + " does not start");
    }
    started_ = true;
    for (auto& r : requests_) camera_->queueRequest(r.get());
  }

  ~LibcameraDevice() override {
    if (started_) camera_->stop();
    if (camera_) camera_->requestCompleted.disconnect(this);
    requests_.clear();
    for (auto& [buffer, m] : maps_) munmap(m.base, m.offset + m.length);
    allocator_.reset();
    if (acquired_) camera_->release();
    camera_.reset();
  }

  const std::string& description() const override { return description_; }
  std::optional<StreamInfo> colour_stream() const override { return stream_info_; }
  std::optional<StreamInfo> depth_stream() const override { return std::nullopt; }

  bool Next(std::chrono::milliseconds timeout, FrameSet& frames) override {
    if (held_ != nullptr) {
      held_->reuse(Request::ReuseBuffers);
      camera_->queueRequest(held_);
      held_ = nullptr;
    }
    std::unique_lock lock(mutex_);
    if (!ready_cv_.wait_for(lock, timeout, [&] { return !completed_.empty(); })) return false;
    Request* request = completed_.front();
    completed_.pop_front();
    lock.unlock();
    held_ = request;
    if (request->status() == Request::RequestCancelled) {
      throw CaptureError(ErrorKind::kDisconnected, description_ + " stopped (unplugged?)");
    }
    FrameBuffer* buffer = request->buffers().begin()->second;
    const Mapping& m = maps_.at(buffer);
    RawFrame f;
    f.format = stream_info_.format;
    f.width = stream_info_.width;
    f.height = stream_info_.height;
    f.stride = stride_;
    const size_t used = buffer->metadata().planes().empty()
                            ? m.length
                            : buffer->metadata().planes().front().bytesused;
    f.data = {m.base + m.offset, f.format == PixelFormat::kMjpeg ? used : m.length};
    f.sequence = buffer->metadata().sequence + 1;
    const auto sensor = request->metadata().get(controls::SensorTimestamp);
    const auto exposure = request->metadata().get(controls::ExposureTime);
    // SensorTimestamp: start of exposure of the first line, CLOCK_MONOTONIC ns.
    f.stamp_mono_ns =
        sensor ? *sensor + (exposure ? *exposure * 500LL : 0) : MonotonicNowNs() - 16'666'667;
    frames.colour = f;
    return true;
  }

 private:
  struct Mapping {
    uint8_t* base = nullptr;
    size_t offset = 0;
    size_t length = 0;
  };
  void OnCompleted(Request* request) {
    {
      std::lock_guard lock(mutex_);
      completed_.push_back(request);
    }
    ready_cv_.notify_one();
  }

  CameraManagerHandle manager_;
  std::shared_ptr<Camera> camera_;
  std::unique_ptr<CameraConfiguration> config_;
  std::unique_ptr<FrameBufferAllocator> allocator_;
  Stream* stream_ = nullptr;
  std::vector<std::unique_ptr<Request>> requests_;
  std::map<const FrameBuffer*, Mapping> maps_;
  std::string description_;
  StreamInfo stream_info_;
  uint32_t stride_ = 0;
  bool acquired_ = false;
  bool started_ = false;
  Request* held_ = nullptr;
  std::mutex mutex_;
  std::condition_variable ready_cv_;
  std::deque<Request*> completed_;
};

}  // namespace

std::vector<std::string> ListLibcameraCameras() {
  CameraManagerHandle manager;
  std::vector<std::string> ids;
  for (const auto& c : manager.get().cameras()) ids.push_back(c->id());
  return ids;
}

std::unique_ptr<Device> OpenLibcamera(const LibcameraOptions& options,
                                      const std::function<void(const std::string&)>& log) {
  return std::make_unique<LibcameraDevice>(options, log);
}

}  // namespace probeless::capture
