// V4L2 backend through libv4l2 (conversion emulation off: we convert ourselves, into the slot).
#include <fcntl.h>
#include <libv4l2.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>

#include "probeless/capture/capture_error.h"
#include "probeless/capture/v4l2.h"

namespace probeless::capture {

// --- Pure parts
// -------------------------------------------------------------------------------------

std::vector<ControlWrite> MapControls(const V4l2Controls& c) {
  std::vector<ControlWrite> w;
  // Auto modes first: a manual value is rejected while its auto mode is on.
  const bool manual_exposure = c.exposure_time_us.has_value();
  if (c.auto_exposure.has_value() || manual_exposure) {
    const bool on = c.auto_exposure.value_or(false) && !manual_exposure;
    w.push_back({V4L2_CID_EXPOSURE_AUTO,
                 on ? V4L2_EXPOSURE_APERTURE_PRIORITY : V4L2_EXPOSURE_MANUAL, "auto_exposure"});
    if (!on) w.push_back({V4L2_CID_EXPOSURE_AUTO_PRIORITY, 0, "auto_exposure"});  // fixed rate
  }
  if (c.auto_white_balance.has_value() || c.white_balance_temperature_k.has_value()) {
    const bool on = c.auto_white_balance.value_or(false) && !c.white_balance_temperature_k;
    w.push_back({V4L2_CID_AUTO_WHITE_BALANCE, on ? 1 : 0, "auto_white_balance"});
  }
  if (c.auto_gain.has_value() || c.gain.has_value()) {
    const bool on = c.auto_gain.value_or(false) && !c.gain;
    w.push_back({V4L2_CID_AUTOGAIN, on ? 1 : 0, "auto_gain"});
  }
  if (c.auto_focus.has_value() || c.focus_absolute.has_value()) {
    const bool on = c.auto_focus.value_or(false) && !c.focus_absolute;
    w.push_back({V4L2_CID_FOCUS_AUTO, on ? 1 : 0, "auto_focus"});
  }
  if (manual_exposure) {
    w.push_back({V4L2_CID_EXPOSURE_ABSOLUTE,
                 std::max<int64_t>(1, std::llround(*c.exposure_time_us / 100.0)),
                 "exposure_time_us"});
  }
  if (c.white_balance_temperature_k) {
    w.push_back({V4L2_CID_WHITE_BALANCE_TEMPERATURE, *c.white_balance_temperature_k,
                 "white_balance_temperature_k"});
  }
  if (c.gain) w.push_back({V4L2_CID_GAIN, *c.gain, "gain"});
  if (c.focus_absolute) w.push_back({V4L2_CID_FOCUS_ABSOLUTE, *c.focus_absolute, "focus_absolute"});
  if (c.brightness) w.push_back({V4L2_CID_BRIGHTNESS, *c.brightness, "brightness"});
  if (c.contrast) w.push_back({V4L2_CID_CONTRAST, *c.contrast, "contrast"});
  if (c.saturation) w.push_back({V4L2_CID_SATURATION, *c.saturation, "saturation"});
  if (c.power_line_frequency) {
    w.push_back({V4L2_CID_POWER_LINE_FREQUENCY, *c.power_line_frequency, "power_line_frequency"});
  }
  return w;
}

std::vector<ControlWrite> LockControls(const V4l2Controls& c) {
  std::vector<ControlWrite> w;
  if (!c.lock_auto) return w;
  if (!c.auto_exposure && !c.exposure_time_us) {
    w.push_back({V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL, "auto_exposure"});
    w.push_back({V4L2_CID_EXPOSURE_AUTO_PRIORITY, 0, "auto_exposure"});
  }
  if (!c.auto_white_balance && !c.white_balance_temperature_k) {
    w.push_back({V4L2_CID_AUTO_WHITE_BALANCE, 0, "auto_white_balance"});
  }
  if (!c.auto_gain && !c.gain) w.push_back({V4L2_CID_AUTOGAIN, 0, "auto_gain"});
  return w;
}

FormatOption ChooseFormat(const std::vector<FormatOption>& offers, const std::string& format,
                          uint32_t width, uint32_t height, double fps, const std::string& device) {
  std::vector<PixelFormat> order;
  if (format == "auto") {
    if (static_cast<uint64_t>(width) * height > 640ull * 480) {
      order = {PixelFormat::kMjpeg, PixelFormat::kYuyv, PixelFormat::kRgb24, PixelFormat::kBgr24,
               PixelFormat::kGrey};
    } else {
      order = {PixelFormat::kYuyv, PixelFormat::kMjpeg, PixelFormat::kRgb24, PixelFormat::kBgr24,
               PixelFormat::kGrey};
    }
  } else {
    order = {PixelFormatFromName(format)};
  }
  auto list = [&] {
    std::string s;
    for (const FormatOption& o : offers) {
      s += std::string(s.empty() ? "" : ", ") + std::string(PixelFormatName(o.format)) + " " +
           std::to_string(o.width) + "x" + std::to_string(o.height);
      if (o.fps > 0) s += "@" + std::to_string(static_cast<int>(std::lround(o.fps)));
    }
    return s.empty() ? std::string("none") : s;
  };
  // Exact size in the preferred format first, then any format at the exact size, then closest.
  for (int pass = 0; pass < 2; ++pass) {
    for (PixelFormat f : order) {
      const FormatOption* best = nullptr;
      double best_score = 1e18;
      for (const FormatOption& o : offers) {
        if (o.format != f) continue;
        const double size_error = std::abs(static_cast<double>(o.width) - width) +
                                  std::abs(static_cast<double>(o.height) - height);
        if (pass == 0 && size_error != 0) continue;
        const double score = size_error * 1000 + (o.fps > 0 ? std::abs(o.fps - fps) : 500);
        if (score < best_score) {
          best_score = score;
          best = &o;
        }
      }
      if (best != nullptr) return *best;
    }
  }
  throw CaptureError(ErrorKind::kBadInput,
                     "V4L2 device '" + device + "' offers no " +
                         (format == "auto" ? std::string("supported") : format) +
                         " format (offers: " + list() + "): set param pixel_format to one of them");
}

std::string ResolveV4l2Device(const std::string& spec, const std::string& by_id_dir) {
  if (spec.starts_with("/")) return spec;
  auto lower = [](std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
    return s;
  };
  const std::string needle = lower(spec);
  std::vector<std::string> entries;
  std::vector<std::string> matches;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(by_id_dir, ec)) {
    const std::string name = e.path().filename().string();
    entries.push_back(name);
    if (lower(name).find(needle) != std::string::npos) matches.push_back(e.path().string());
  }
  std::sort(matches.begin(), matches.end());
  std::vector<std::string> index0;
  for (const auto& m : matches) {
    if (m.ends_with("-video-index0")) index0.push_back(m);
  }
  if (index0.size() == 1) return index0.front();
  if (index0.size() > 1) {
    std::string all;
    for (const auto& m : index0) all += std::string(all.empty() ? "" : ", ") + m;
    throw CaptureError(ErrorKind::kBadInput, "V4L2 camera name '" + spec + "' matches " +
                                                 std::to_string(index0.size()) + " cameras (" +
                                                 all + "): give more of the name or the serial");
  }
  if (!matches.empty()) return matches.front();
  std::sort(entries.begin(), entries.end());
  std::string all;
  for (const auto& m : entries) all += std::string(all.empty() ? "" : ", ") + m;
  throw CaptureError(ErrorKind::kNoDevice,
                     "no V4L2 camera named '" + spec + "' in " + by_id_dir + " (" +
                         (all.empty() ? std::string("no camera connected") : "found: " + all) +
                         "): plug it in or fix param device");
}

// --- The device
// -------------------------------------------------------------------------------------

namespace {

std::optional<PixelFormat> FromFourcc(uint32_t fourcc) {
  switch (fourcc) {
    case V4L2_PIX_FMT_YUYV:
      return PixelFormat::kYuyv;
    case V4L2_PIX_FMT_MJPEG:
    case V4L2_PIX_FMT_JPEG:
      return PixelFormat::kMjpeg;
    case V4L2_PIX_FMT_RGB24:
      return PixelFormat::kRgb24;
    case V4L2_PIX_FMT_BGR24:
      return PixelFormat::kBgr24;
    case V4L2_PIX_FMT_GREY:
      return PixelFormat::kGrey;
    default:
      return std::nullopt;
  }
}

uint32_t ToFourcc(PixelFormat f) {
  switch (f) {
    case PixelFormat::kYuyv:
      return V4L2_PIX_FMT_YUYV;
    case PixelFormat::kMjpeg:
      return V4L2_PIX_FMT_MJPEG;
    case PixelFormat::kRgb24:
      return V4L2_PIX_FMT_RGB24;
    case PixelFormat::kBgr24:
      return V4L2_PIX_FMT_BGR24;
    case PixelFormat::kGrey:
      return V4L2_PIX_FMT_GREY;
    default:
      return 0;
  }
}

int Xioctl(int fd, unsigned long request, void* arg) {
  int r;
  do {
    r = v4l2_ioctl(fd, request, arg);
  } while (r == -1 && errno == EINTR);
  return r;
}

class V4l2Device final : public Device {
 public:
  V4l2Device(const V4l2Options& options, const std::function<void(const std::string&)>& log)
      : options_(options), log_(log) {
    path_ = ResolveV4l2Device(options.device, options.by_id_dir);
    description_ = "V4L2 device '" + path_ + "'";
    const int raw_fd = ::open(path_.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
    if (raw_fd < 0) Fail(errno, "cannot be opened");
    v4l2_capability probe{};
    if (::ioctl(raw_fd, VIDIOC_QUERYCAP, &probe) < 0) {
      const int e = errno;
      ::close(raw_fd);
      Fail(e, "does not answer VIDIOC_QUERYCAP");
    }
    fd_ = v4l2_fd_open(raw_fd, V4L2_DISABLE_CONVERSION);
    if (fd_ < 0) {
      const int e = errno;
      ::close(raw_fd);
      Fail(e, "cannot be opened by libv4l2");
    }
    // A device that fails half-way is released here (no destructor runs for a throwing
    // constructor): a leaked descriptor would keep its buffer queue (EBUSY on every retry).
    try {
      Setup();
    } catch (...) {
      Release();
      throw;
    }
  }

  ~V4l2Device() override { Release(); }

  const std::string& description() const override { return description_; }
  std::optional<StreamInfo> colour_stream() const override { return stream_; }
  std::optional<StreamInfo> depth_stream() const override { return std::nullopt; }

  bool Next(std::chrono::milliseconds timeout, FrameSet& frames) override {
    Requeue();
    if (lock_pending_ && std::chrono::steady_clock::now() >= lock_at_) {
      lock_pending_ = false;
      for (const ControlWrite& w : LockControls(options_.controls)) SetControl(w);
      log_(description_ + ": locked auto exposure / white balance / gain (" + ReadBack() + ")");
    }
    pollfd p{fd_, POLLIN, 0};
    const int r = ::poll(&p, 1, static_cast<int>(timeout.count()));
    if (r == 0) return false;
    if (r < 0) {
      if (errno == EINTR) return false;
      Fail(errno, "poll failed");
    }
    if (p.revents & (POLLERR | POLLHUP | POLLNVAL)) {
      throw CaptureError(ErrorKind::kDisconnected,
                         description_ + " went away (unplugged?): plug it back in");
    }
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    if (Xioctl(fd_, VIDIOC_DQBUF, &buf) < 0) {
      if (errno == EAGAIN) return false;
      if (errno == ENODEV || errno == EIO) {
        throw CaptureError(ErrorKind::kDisconnected,
                           description_ + " went away (unplugged?): plug it back in");
      }
      Fail(errno, "VIDIOC_DQBUF failed");
    }
    held_ = static_cast<int>(buf.index);
    if (buf.flags & V4L2_BUF_FLAG_ERROR) {
      // The driver says the data may be corrupt (e.g. a USB packet lost): the frame is dropped,
      // the buffer requeued by the next call.
      ++error_buffers_;
      if (error_buffers_ <= 10 || error_buffers_ % 100 == 0) {
        log_(description_ + ": dropped a buffer the driver flagged as erroneous (" +
             std::to_string(error_buffers_) + " so far)");
      }
      return false;
    }
    RawFrame f;
    f.format = stream_.format;
    f.width = stream_.width;
    f.height = stream_.height;
    f.stride = stride_;
    f.data = {static_cast<const uint8_t*>(buffers_[buf.index].first), buf.bytesused};
    f.sequence = buf.sequence + 1;
    const int64_t ts = static_cast<int64_t>(buf.timestamp.tv_sec) * 1'000'000'000 +
                       static_cast<int64_t>(buf.timestamp.tv_usec) * 1000;
    const int64_t period = stream_.fps > 0 ? static_cast<int64_t>(1e9 / stream_.fps) : 33'333'333;
    if ((buf.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC && ts > 0) {
      // Start of exposure: add half an exposure; end of frame: subtract half a frame period.
      const bool soe = (buf.flags & V4L2_BUF_FLAG_TSTAMP_SRC_MASK) == V4L2_BUF_FLAG_TSTAMP_SRC_SOE;
      const int64_t half_exposure =
          options_.controls.exposure_time_us
              ? static_cast<int64_t>(*options_.controls.exposure_time_us * 500)
              : period / 4;
      f.stamp_mono_ns = soe ? ts + half_exposure : ts - period / 2;
    } else {
      f.stamp_mono_ns = MonotonicNowNs() - period / 2;
    }
    if (f.format != PixelFormat::kMjpeg) f.data = {f.data.data(), buffers_[buf.index].second};
    frames.colour = f;
    return true;
  }

 private:
  [[noreturn]] void Fail(int error, const std::string& what) {
    const std::string detail = what + " (" + std::strerror(error) + ")";
    switch (error) {
      case ENOENT:
      case ENODEV:
      case ENXIO:
        throw CaptureError(ErrorKind::kNoDevice,
                           description_ +
                               " does not exist: plug the camera in or pick another "
                               "with param device (ls /dev/v4l/by-id)");
      case EACCES:
      case EPERM:
        throw CaptureError(ErrorKind::kPermission,
                           description_ +
                               ": permission denied: add your user to group 'video' "
                               "(sudo usermod -aG video $USER, then log in again)");
      case EBUSY:
        throw CaptureError(ErrorKind::kBusy, description_ +
                                                 " is busy: another process streams from it "
                                                 "(fuser " +
                                                 path_ + ")");
      case ENOTTY:
      case EINVAL:
        throw CaptureError(ErrorKind::kBadInput,
                           description_ + " is not a V4L2 video device: " + detail);
      default:
        throw CaptureError(ErrorKind::kDeviceError, description_ + " " + detail);
    }
  }

  // Checks the capabilities, negotiates, applies the explicit controls and starts streaming.
  void Setup() {
    v4l2_capability cap{};
    if (Xioctl(fd_, VIDIOC_QUERYCAP, &cap) < 0) {
      Fail(errno == ENOTTY ? ENOTTY : errno, "does not answer VIDIOC_QUERYCAP");
    }
    description_ += " (" + std::string(reinterpret_cast<const char*>(cap.card)) + ")";
    const uint32_t caps =
        (cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
    if (!(caps & V4L2_CAP_VIDEO_CAPTURE) || !(caps & V4L2_CAP_STREAMING)) {
      throw CaptureError(ErrorKind::kBadInput,
                         description_ +
                             " is not a streaming video-capture node (a metadata "
                             "node?): use the -video-index0 entry of /dev/v4l/by-id");
    }
    Negotiate();
    for (const ControlWrite& w : MapControls(options_.controls)) SetControl(w);
    StartStreaming();
    lock_at_ =
        std::chrono::steady_clock::now() +
        std::chrono::milliseconds(static_cast<int64_t>(options_.controls.lock_after_s * 1000));
    lock_pending_ = !LockControls(options_.controls).empty();
  }

  // Stops streaming, unmaps the buffers and closes the device (idempotent).
  void Release() {
    if (fd_ < 0) return;
    v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    Xioctl(fd_, VIDIOC_STREAMOFF, &type);
    for (auto& b : buffers_) v4l2_munmap(b.first, b.second);
    buffers_.clear();
    v4l2_close(fd_);
    fd_ = -1;
  }

  void Negotiate() {
    std::vector<FormatOption> offers;
    v4l2_fmtdesc desc{};
    desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    for (desc.index = 0; Xioctl(fd_, VIDIOC_ENUM_FMT, &desc) == 0; ++desc.index) {
      const std::optional<PixelFormat> pf = FromFourcc(desc.pixelformat);
      if (!pf) continue;
      v4l2_frmsizeenum size{};
      size.pixel_format = desc.pixelformat;
      for (size.index = 0; Xioctl(fd_, VIDIOC_ENUM_FRAMESIZES, &size) == 0; ++size.index) {
        if (size.type != V4L2_FRMSIZE_TYPE_DISCRETE) {
          offers.push_back({*pf, options_.width, options_.height, 0});
          break;
        }
        v4l2_frmivalenum ival{};
        ival.pixel_format = desc.pixelformat;
        ival.width = size.discrete.width;
        ival.height = size.discrete.height;
        bool any = false;
        for (ival.index = 0; Xioctl(fd_, VIDIOC_ENUM_FRAMEINTERVALS, &ival) == 0; ++ival.index) {
          if (ival.type != V4L2_FRMIVAL_TYPE_DISCRETE || ival.discrete.numerator == 0) break;
          offers.push_back(
              {*pf, size.discrete.width, size.discrete.height,
               static_cast<double>(ival.discrete.denominator) / ival.discrete.numerator});
          any = true;
        }
        if (!any) offers.push_back({*pf, size.discrete.width, size.discrete.height, 0});
      }
    }
    const FormatOption choice = ChooseFormat(offers, options_.pixel_format, options_.width,
                                             options_.height, options_.fps, path_);
    v4l2_format fmt{};
    fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    fmt.fmt.pix.width = choice.width;
    fmt.fmt.pix.height = choice.height;
    fmt.fmt.pix.pixelformat = ToFourcc(choice.format);
    fmt.fmt.pix.field = V4L2_FIELD_NONE;
    if (Xioctl(fd_, VIDIOC_S_FMT, &fmt) < 0) Fail(errno, "rejects the format");
    const std::optional<PixelFormat> got = FromFourcc(fmt.fmt.pix.pixelformat);
    if (!got) {
      throw CaptureError(ErrorKind::kBadInput, description_ + " switched to an unsupported format");
    }
    stream_ = StreamInfo{*got, fmt.fmt.pix.width, fmt.fmt.pix.height, choice.fps};
    stride_ = *got == PixelFormat::kMjpeg ? 0 : fmt.fmt.pix.bytesperline;
    v4l2_streamparm parm{};
    parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    parm.parm.capture.timeperframe.numerator = 1000;
    parm.parm.capture.timeperframe.denominator =
        static_cast<uint32_t>(std::lround((choice.fps > 0 ? choice.fps : options_.fps) * 1000));
    if (Xioctl(fd_, VIDIOC_S_PARM, &parm) == 0 && parm.parm.capture.timeperframe.numerator != 0) {
      stream_.fps = static_cast<double>(parm.parm.capture.timeperframe.denominator) /
                    parm.parm.capture.timeperframe.numerator;
    }
  }

  void SetControl(const ControlWrite& w) {
    v4l2_control control{};
    control.id = w.id;
    control.value = static_cast<int32_t>(w.value);
    if (Xioctl(fd_, VIDIOC_S_CTRL, &control) < 0) {
      // A camera without the control is not an error worth stopping for, but it is reported.
      log_(description_ + ": control '" + w.name + "' = " + std::to_string(w.value) +
           " not applied (" + std::strerror(errno) + ")");
    }
  }

  std::string ReadBack() {
    std::string s;
    for (auto [id, name] :
         {std::pair<uint32_t, const char*>{V4L2_CID_EXPOSURE_ABSOLUTE, "exposure_time_us/100"},
          {V4L2_CID_GAIN, "gain"},
          {V4L2_CID_WHITE_BALANCE_TEMPERATURE, "white_balance_temperature_k"}}) {
      v4l2_control c{};
      c.id = id;
      if (Xioctl(fd_, VIDIOC_G_CTRL, &c) == 0) {
        s += std::string(s.empty() ? "" : ", ") + name + " " + std::to_string(c.value);
      }
    }
    return s.empty() ? "no values readable" : s;
  }

  void StartStreaming() {
    v4l2_requestbuffers req{};
    req.count = std::max<uint32_t>(2, options_.buffers);
    req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    req.memory = V4L2_MEMORY_MMAP;
    if (Xioctl(fd_, VIDIOC_REQBUFS, &req) < 0) Fail(errno, "refuses mmap buffers");
    for (uint32_t i = 0; i < req.count; ++i) {
      v4l2_buffer buf{};
      buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      buf.memory = V4L2_MEMORY_MMAP;
      buf.index = i;
      if (Xioctl(fd_, VIDIOC_QUERYBUF, &buf) < 0) Fail(errno, "VIDIOC_QUERYBUF failed");
      void* p =
          v4l2_mmap(nullptr, buf.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, buf.m.offset);
      if (p == MAP_FAILED) Fail(errno, "mmap failed");
      buffers_.emplace_back(p, buf.length);
      if (Xioctl(fd_, VIDIOC_QBUF, &buf) < 0) Fail(errno, "VIDIOC_QBUF failed");
    }
    v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (Xioctl(fd_, VIDIOC_STREAMON, &type) < 0) Fail(errno, "does not start streaming");
  }

  void Requeue() {
    if (held_ < 0) return;
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = static_cast<uint32_t>(held_);
    held_ = -1;
    if (Xioctl(fd_, VIDIOC_QBUF, &buf) < 0) {
      throw CaptureError(ErrorKind::kDisconnected,
                         description_ + " went away (unplugged?): plug it back in");
    }
  }

  V4l2Options options_;
  std::function<void(const std::string&)> log_;
  uint64_t error_buffers_ = 0;  // buffers dequeued with V4L2_BUF_FLAG_ERROR
  std::string path_;
  std::string description_;
  int fd_ = -1;
  StreamInfo stream_;
  uint32_t stride_ = 0;
  std::vector<std::pair<void*, size_t>> buffers_;
  int held_ = -1;
  bool lock_pending_ = false;
  std::chrono::steady_clock::time_point lock_at_;
};

}  // namespace

std::unique_ptr<Device> OpenV4l2(const V4l2Options& options,
                                 const std::function<void(const std::string&)>& log) {
  return std::make_unique<V4l2Device>(options, log);
}

}  // namespace probeless::capture
