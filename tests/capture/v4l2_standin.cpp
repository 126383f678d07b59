// libprobeless_v4l2_standin.so: a user-space stand-in for one V4L2 camera behind libv4l2, loaded
// with LD_PRELOAD into the real capture_v4l2 binary (as fakenect stands in for libfreenect), so
// the node's own streaming code runs without a camera. It interposes the calls that code makes -
// libc open/open64/__open_2/__open64_2, ioctl and close, libv4l2 v4l2_fd_open, v4l2_ioctl,
// v4l2_mmap, v4l2_munmap and v4l2_close - for one device path; every other path and descriptor
// goes to the next definition (libc's, libv4l2's) through dlsym(RTLD_NEXT).
//
// Environment (read at the first open of the device; a bad value prints one line and that open
// fails with EINVAL, which the node reports as not a V4L2 device and does not retry):
//   PROBELESS_V4L2_STANDIN_DEVICE  the device path (need not exist); unset = everything passes on
//   PROBELESS_V4L2_STANDIN_SIZE    WIDTHxHEIGHT of the recordings (640x480)
//   PROBELESS_V4L2_STANDIN_YUYV    a recording of YUYV frames back to back (v4l2-ctl --stream-to)
//   PROBELESS_V4L2_STANDIN_MJPEG   a recording of JPEG frames back to back (an MJPEG stream)
//   PROBELESS_V4L2_STANDIN_STATE   a file holding "unplugged" or "busy"; absent/else = plugged in
//   PROBELESS_V4L2_STANDIN_CORRUPT served MJPEG frames sent corrupt: indices "3,4" or "all" (needs
//                                  _MJPEG; a YUYV stream is served as recorded)
//   PROBELESS_V4L2_STANDIN_ERROR_FLAG  served buffers flagged V4L2_BUF_FLAG_ERROR: "6" or "all"
//   PROBELESS_V4L2_STANDIN_LOG     event log: "<CLOCK_MONOTONIC ns> <event> key=value ..." lines
//
// The device: the recorded formats at one size, 30 or 15 frames/s (VIDIOC_S_PARM picks the
// closer), mmap streaming (REQBUFS up to 32 buffers in a memfd, QUERYBUF, mmap, QBUF, DQBUF,
// STREAMON/STREAMOFF; non-blocking DQBUF says EAGAIN). The descriptor is the read end of a pipe:
// a frame clock thread (ticks at STREAMON + k periods) fills the oldest queued buffer with frame
// k of the recording (cyclically; no queued buffer = the frame is dropped, logged) and writes one
// byte, so an unmodified poll() sees POLLIN; buffers carry sequence k and a monotonic start-of-
// exposure timestamp (the tick minus half a period, in µs). Controls (QUERYCTRL, G_CTRL, S_CTRL)
// as a UVC webcam has them: exposure_auto (menu 1 manual, 3 aperture priority; default 3),
// exposure_auto_priority (1), exposure_absolute (3..2047, 250), auto_white_balance (1),
// white_balance_temperature (2000..6500, 4000), autogain (1), gain (0..255, 0). While an auto
// mode is on, its value follows a changing scene every frame and writing it fails with EACCES
// (as recent uvcvideo does); switching the auto mode off keeps the value reached. Unknown
// controls: EINVAL. Unplug ("unplugged" in the state file, seen within 5 ms while streaming, else
// at the next call): the write end is closed (poll: POLLHUP), every ioctl and mmap of an open
// descriptor fails with ENODEV, open fails with ENOENT, controls return to their defaults; replug
// (the state changes back): open succeeds again. "busy": S_FMT, S_PARM and REQBUFS fail with
// EBUSY (another process streams). Damaged frames, by served-frame index (0 = the first frame
// put in a buffer after STREAMON; = its sequence unless frames were dropped): a corrupt one is
// the recorded JPEG truncated to its first kCorruptBytes bytes (bytesused says so; the rest of
// the buffer keeps the previous frame, as after a short USB transfer), logged as "corrupt"; a
// flagged one carries its recorded data with V4L2_BUF_FLAG_ERROR, logged as "flagged" (both:
// "flagged", truncated). Not emulated: read() I/O, other ioctls (ENOTTY, one line each), several
// streaming descriptors at once (EBUSY), frames truncated inside their scan data.
#include <dlfcn.h>
#include <fcntl.h>
#include <libv4l2.h>
#include <linux/videodev2.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <condition_variable>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

extern "C" {
// Declared by glibc only with _FORTIFY_SOURCE; interposed for callers built with it.
int __open_2(const char* path, int flags);
int __open64_2(const char* path, int flags);
}

namespace {

// --- The next definitions (libc, libv4l2) -------------------------------------------------------

using OpenFn = int (*)(const char*, int, ...);
using Open2Fn = int (*)(const char*, int);
using CloseFn = int (*)(int);
using IoctlFn = int (*)(int, unsigned long, ...);
using FdOpenFn = int (*)(int, int);
using MmapFn = void* (*)(void*, size_t, int, int, int, int64_t);
using MunmapFn = int (*)(void*, size_t);

// The definition of `name` that this library hides (null when no later object defines it).
template <class F>
F NextDefinition(const char* name) {
  return reinterpret_cast<F>(dlsym(RTLD_NEXT, name));
}

// The hidden definitions, looked up once.
struct NextFunctions {
  OpenFn open = NextDefinition<OpenFn>("open");
  OpenFn open64 = NextDefinition<OpenFn>("open64");
  Open2Fn open_2 = NextDefinition<Open2Fn>("__open_2");
  Open2Fn open64_2 = NextDefinition<Open2Fn>("__open64_2");
  CloseFn close = NextDefinition<CloseFn>("close");
  IoctlFn ioctl = NextDefinition<IoctlFn>("ioctl");
  FdOpenFn v4l2_fd_open = NextDefinition<FdOpenFn>("v4l2_fd_open");
  CloseFn v4l2_close = NextDefinition<CloseFn>("v4l2_close");
  IoctlFn v4l2_ioctl = NextDefinition<IoctlFn>("v4l2_ioctl");
  MmapFn v4l2_mmap = NextDefinition<MmapFn>("v4l2_mmap");
  MunmapFn v4l2_munmap = NextDefinition<MunmapFn>("v4l2_munmap");
};

// The hidden definitions (resolved at first use: open() may run before this library's init).
const NextFunctions& Next() {
  static const NextFunctions next;
  return next;
}

// CLOCK_MONOTONIC now, ns (the clock V4L2 timestamps and the node's stamps use).
int64_t NowNs() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);
  return static_cast<int64_t>(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
}

// --- Configuration ----------------------------------------------------------------------------

constexpr const char* kDeviceEnv = "PROBELESS_V4L2_STANDIN_DEVICE";
constexpr const char* kSizeEnv = "PROBELESS_V4L2_STANDIN_SIZE";
constexpr const char* kYuyvEnv = "PROBELESS_V4L2_STANDIN_YUYV";
constexpr const char* kMjpegEnv = "PROBELESS_V4L2_STANDIN_MJPEG";
constexpr const char* kStateEnv = "PROBELESS_V4L2_STANDIN_STATE";
constexpr const char* kCorruptEnv = "PROBELESS_V4L2_STANDIN_CORRUPT";
constexpr const char* kErrorFlagEnv = "PROBELESS_V4L2_STANDIN_ERROR_FLAG";
constexpr const char* kLogEnv = "PROBELESS_V4L2_STANDIN_LOG";
constexpr uint32_t kMaxBuffers = 32;
// Bytes a corrupt MJPEG frame keeps: SOI and the start of the first segment, so the node's
// decoder gets a JPEG that ends inside its headers (an error, never a padded image).
constexpr size_t kCorruptBytes = 16;

// The environment variable `name`, "" if unset.
std::string Env(const char* name) {
  const char* v = std::getenv(name);
  return v == nullptr ? std::string() : std::string(v);
}

// The emulated device path ("" = the stand-in is off). Only getenv: open() calls it for every
// path, also while the configuration below reads its files. Never destroyed: close() and the
// exit report run after static destructors.
const std::string& DevicePath() {
  static const std::string* path = new std::string(Env(kDeviceEnv));
  return *path;
}

// Served-frame indices of one kind of damage (counted per STREAMON from 0).
struct FrameList {
  bool all = false;
  std::set<uint64_t> indices;
  // Whether served frame `n` is on the list.
  bool Contains(uint64_t n) const { return all || indices.contains(n); }
};

// The recordings and files named by the environment.
struct Config {
  uint32_t width = 640;
  uint32_t height = 480;
  std::vector<std::string> yuyv;   // frames of width * height * 2 bytes
  std::vector<std::string> mjpeg;  // one JPEG each
  std::string state_path;
  FrameList corrupt;     // MJPEG frames served truncated to kCorruptBytes
  FrameList error_flag;  // buffers served with V4L2_BUF_FLAG_ERROR
  std::string error;     // the first configuration error ("" = usable)
};

// The whole file `path` into `out`; false (and `error` set) if it cannot be read.
bool ReadFile(const std::string& variable, const std::string& path, std::string& out,
              std::string& error) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) {
    error = variable + " '" + path + "' cannot be read (" + std::strerror(errno) + ")";
    return false;
  }
  char chunk[1 << 16];
  for (size_t n; (n = std::fread(chunk, 1, sizeof chunk, f)) > 0;) out.append(chunk, n);
  std::fclose(f);
  if (out.empty()) error = variable + " '" + path + "' is empty";
  return !out.empty();
}

// Splits an MJPEG recording (JPEGs back to back) at the markers of each image: SOI, segments up
// to SOS, entropy-coded data up to the next marker that is not a restart or a stuffed 0xFF, ...,
// EOI. Checks each frame's size (SOFn) against the configured one. Sets `error` on failure.
std::vector<std::string> SplitJpegs(const std::string& data, uint32_t width, uint32_t height,
                                    std::string& error) {
  std::vector<std::string> frames;
  const auto* d = reinterpret_cast<const uint8_t*>(data.data());
  const size_t n = data.size();
  size_t pos = 0;
  auto fail = [&](const std::string& what, size_t at) {
    error = std::string(kMjpegEnv) + ": frame " + std::to_string(frames.size()) + " " + what +
            " at byte " + std::to_string(at) + " (expected JPEG images back to back)";
    return std::vector<std::string>();
  };
  while (pos < n) {
    if (pos + 1 >= n || d[pos] != 0xFF || d[pos + 1] != 0xD8) return fail("has no SOI marker", pos);
    size_t i = pos + 2;
    uint32_t w = 0;
    uint32_t h = 0;
    bool end = false;
    while (!end) {
      if (i + 1 >= n || d[i] != 0xFF) return fail("is truncated or malformed", i);
      while (i + 1 < n && d[i + 1] == 0xFF) ++i;  // fill bytes
      if (i + 1 >= n) return fail("is truncated", i);
      const uint8_t marker = d[i + 1];
      i += 2;
      if (marker == 0xD9) {
        end = true;
        break;
      }
      if ((marker >= 0xD0 && marker <= 0xD7) || marker == 0x01) continue;  // no length
      if (i + 1 >= n) return fail("is truncated", i);
      const size_t length = (static_cast<size_t>(d[i]) << 8) | d[i + 1];
      if (length < 2 || i + length > n) return fail("has a bad segment length", i);
      const bool sof =
          marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
      if (sof && length >= 7) {
        h = (static_cast<uint32_t>(d[i + 3]) << 8) | d[i + 4];
        w = (static_cast<uint32_t>(d[i + 5]) << 8) | d[i + 6];
      }
      i += length;
      if (marker == 0xDA) {
        // Entropy-coded data: 0xFF is followed by 0x00 (stuffing) or a restart marker inside it.
        while (i + 1 < n &&
               !(d[i] == 0xFF && d[i + 1] != 0x00 && !(d[i + 1] >= 0xD0 && d[i + 1] <= 0xD7))) {
          ++i;
        }
      }
    }
    if (w != width || h != height) {
      return fail("is " + std::to_string(w) + "x" + std::to_string(h) + ", " + kSizeEnv + " says " +
                      std::to_string(width) + "x" + std::to_string(height),
                  pos);
    }
    if (i - pos > static_cast<size_t>(width) * height * 2) {
      return fail("is larger than a buffer (width * height * 2 bytes)", pos);
    }
    frames.emplace_back(data.substr(pos, i - pos));
    pos = i;
  }
  return frames;
}

// `text` of variable `name` ("" = none, "all", or indices such as "3,4") into `out`; false (and
// `error` set) if it is neither.
bool ParseFrameList(const char* name, const std::string& text, FrameList& out, std::string& error) {
  if (text == "all") {
    out.all = true;
    return true;
  }
  for (size_t pos = 0; pos < text.size();) {
    const size_t end = std::min(text.find(',', pos), text.size());
    uint64_t n = 0;
    const auto [stop, ec] = std::from_chars(text.data() + pos, text.data() + end, n);
    if (end == pos || ec != std::errc() || stop != text.data() + end || end + 1 == text.size()) {
      error = std::string(name) + " '" + text +
              "' is not a comma-separated list of served-frame indices (e.g. 3,4) or all";
      return false;
    }
    out.indices.insert(n);
    pos = end + 1;
  }
  return true;
}

// Reads and checks the environment (once).
Config LoadConfig() {
  Config c;
  const std::string size = Env(kSizeEnv);
  if (!size.empty()) {
    unsigned w = 0;
    unsigned h = 0;
    char tail = 0;
    if (std::sscanf(size.c_str(), "%ux%u%c", &w, &h, &tail) != 2 || w == 0 || h == 0 || w % 2 ||
        w > 8192 || h > 8192) {
      c.error = std::string(kSizeEnv) + " '" + size +
                "' is not WIDTHxHEIGHT with an even width up to 8192 (e.g. 640x480)";
      return c;
    }
    c.width = w;
    c.height = h;
  }
  const std::string yuyv = Env(kYuyvEnv);
  const std::string mjpeg = Env(kMjpegEnv);
  if (!ParseFrameList(kCorruptEnv, Env(kCorruptEnv), c.corrupt, c.error) ||
      !ParseFrameList(kErrorFlagEnv, Env(kErrorFlagEnv), c.error_flag, c.error)) {
    return c;
  }
  if ((c.corrupt.all || !c.corrupt.indices.empty()) && mjpeg.empty()) {
    c.error = std::string(kCorruptEnv) + " needs " + kMjpegEnv +
              " (only MJPEG frames are served corrupt)";
    return c;
  }
  if (yuyv.empty() && mjpeg.empty()) {
    c.error = std::string("set ") + kYuyvEnv + " and/or " + kMjpegEnv + " to a recording";
    return c;
  }
  if (!yuyv.empty()) {
    std::string data;
    if (!ReadFile(kYuyvEnv, yuyv, data, c.error)) return c;
    const size_t frame = static_cast<size_t>(c.width) * c.height * 2;
    if (data.size() % frame != 0) {
      c.error = std::string(kYuyvEnv) + " '" + yuyv + "': " + std::to_string(data.size()) +
                " bytes is not a whole number of " + std::to_string(c.width) + "x" +
                std::to_string(c.height) + " YUYV frames (" + std::to_string(frame) +
                " bytes each)";
      return c;
    }
    for (size_t p = 0; p < data.size(); p += frame) c.yuyv.emplace_back(data.substr(p, frame));
  }
  if (!mjpeg.empty()) {
    std::string data;
    if (!ReadFile(kMjpegEnv, mjpeg, data, c.error)) return c;
    c.mjpeg = SplitJpegs(data, c.width, c.height, c.error);
    if (!c.error.empty()) return c;
  }
  c.state_path = Env(kStateEnv);
  return c;
}

// The configuration, loaded at the first open of the device (never destroyed: a clock thread
// may still read it while the process exits).
const Config& GetConfig() {
  static const Config* config = new Config(LoadConfig());
  return *config;
}

// --- Event log --------------------------------------------------------------------------------

// Appends "<monotonic ns> <printf text>" as one line (one write: lines of threads never mix).
__attribute__((format(printf, 1, 2))) void Log(const char* format, ...) {
  static const int fd = [] {
    const std::string path = Env(kLogEnv);
    return path.empty()
               ? -1
               : Next().open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  }();
  if (fd < 0) return;
  char line[512];
  int n = std::snprintf(line, sizeof line, "%lld ", static_cast<long long>(NowNs()));
  va_list args;
  va_start(args, format);
  n += std::vsnprintf(line + n, sizeof line - n - 1, format, args);
  va_end(args);
  n = std::min<int>(n, sizeof line - 2);
  line[n++] = '\n';
  [[maybe_unused]] const ssize_t written = ::write(fd, line, n);
}

// One line on stderr, as the nodes print theirs.
void PrintError(const std::string& what) {
  std::fprintf(stderr, "[error] [v4l2_standin] %s\n", what.c_str());
}

// --- The camera -------------------------------------------------------------------------------

enum class DeviceState { kPlugged, kUnplugged, kBusy };

// The state file's word (plugged in when there is none).
DeviceState ReadState(const Config& config) {
  if (config.state_path.empty()) return DeviceState::kPlugged;
  const int fd = Next().open(config.state_path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return DeviceState::kPlugged;
  char text[32] = {};
  const ssize_t n = ::read(fd, text, sizeof text - 1);
  Next().close(fd);
  const std::string word(text, n > 0 ? static_cast<size_t>(n) : 0);
  if (word.starts_with("unplugged")) return DeviceState::kUnplugged;
  if (word.starts_with("busy")) return DeviceState::kBusy;
  return DeviceState::kPlugged;
}

// One V4L2 control of the emulated camera.
struct Control {
  uint32_t id = 0;
  const char* name = "";
  uint32_t type = V4L2_CTRL_TYPE_INTEGER;
  int32_t minimum = 0;
  int32_t maximum = 0;
  int32_t step = 1;
  int32_t default_value = 0;
  uint32_t menu_mask = 0;     // menus: bit v set = item v exists
  uint32_t master = 0;        // the auto-mode control that makes this one inactive (0 = none)
  int32_t master_manual = 0;  // the master's value meaning manual
  int32_t value = 0;
};

// The controls of a typical UVC webcam, sorted by id (for V4L2_CTRL_FLAG_NEXT_CTRL).
std::vector<Control> DefaultControls() {
  std::vector<Control> c = {
      {V4L2_CID_AUTO_WHITE_BALANCE, "auto_white_balance", V4L2_CTRL_TYPE_BOOLEAN, 0, 1, 1, 1},
      {V4L2_CID_AUTOGAIN, "autogain", V4L2_CTRL_TYPE_BOOLEAN, 0, 1, 1, 1},
      {V4L2_CID_GAIN, "gain", V4L2_CTRL_TYPE_INTEGER, 0, 255, 1, 0, 0, V4L2_CID_AUTOGAIN, 0},
      {V4L2_CID_WHITE_BALANCE_TEMPERATURE, "white_balance_temperature", V4L2_CTRL_TYPE_INTEGER,
       2000, 6500, 1, 4000, 0, V4L2_CID_AUTO_WHITE_BALANCE, 0},
      {V4L2_CID_EXPOSURE_AUTO, "exposure_auto", V4L2_CTRL_TYPE_MENU, 0, 3, 1,
       V4L2_EXPOSURE_APERTURE_PRIORITY,
       (1u << V4L2_EXPOSURE_MANUAL) | (1u << V4L2_EXPOSURE_APERTURE_PRIORITY)},
      {V4L2_CID_EXPOSURE_ABSOLUTE, "exposure_absolute", V4L2_CTRL_TYPE_INTEGER, 3, 2047, 1, 250, 0,
       V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL},
      {V4L2_CID_EXPOSURE_AUTO_PRIORITY, "exposure_auto_priority", V4L2_CTRL_TYPE_BOOLEAN, 0, 1, 1,
       1},
  };
  for (Control& k : c) k.value = k.default_value;
  std::sort(c.begin(), c.end(), [](const Control& a, const Control& b) { return a.id < b.id; });
  return c;
}

// One mmap buffer of a descriptor.
struct Buffer {
  enum class State { kDequeued, kQueued, kDone };
  State state = State::kDequeued;
  uint32_t bytesused = 0;
  uint32_t sequence = 0;
  bool error = false;        // served with V4L2_BUF_FLAG_ERROR
  int64_t timestamp_ns = 0;  // whole microseconds, as a timeval carries it
  int mapped = 0;            // live v4l2_mmap mappings
};

// One open descriptor of the device.
struct Handle {
  int id = 0;          // for the log: opens are numbered from 1
  int fd = -1;         // the pipe's read end, the descriptor the caller holds
  int signal_fd = -1;  // the pipe's write end: one byte per done buffer; closed at unplug
  bool nonblocking = false;
  bool dead = false;  // unplugged while open: ENODEV from now on
  uint32_t fourcc = 0;
  uint32_t fps = 30;
  int memfd = -1;
  uint8_t* memory = nullptr;  // this library's own mapping of all buffers
  size_t buffer_stride = 0;   // page-aligned distance of buffers in the memfd (= mmap offsets)
  std::vector<Buffer> buffers;
  std::deque<uint32_t> queued;
  std::deque<uint32_t> done;
  bool streaming = false;
  bool stop_clock = false;
  uint64_t ticks = 0;
  uint64_t served = 0;  // frames put in buffers since STREAMON (the damage lists' index)
  std::thread clock;
  std::condition_variable wake;  // a frame is done, the clock must stop, or the device went away
};

// A mapping handed out by v4l2_mmap.
struct Mapping {
  std::weak_ptr<Handle> handle;
  uint32_t index = 0;
};

// The camera of this process: controls, open descriptors, mappings; one mutex guards all.
struct Camera {
  std::mutex mutex;
  std::vector<Control> controls = DefaultControls();
  std::map<int, std::shared_ptr<Handle>> handles;  // by fd
  std::map<void*, Mapping> mappings;
  Handle* streamer = nullptr;  // the descriptor that owns the buffers
  bool unplugged = false;      // the last state seen
  int opens = 0;
  std::set<unsigned long> reported_requests;
};

// The camera (never destroyed: a clock thread of a descriptor the caller leaked may still run
// while the process exits).
Camera& TheCamera() {
  static Camera* camera = new Camera;
  return *camera;
}

// The control `id` of the camera, null if it has none.
Control* FindControl(Camera& camera, uint32_t id) {
  for (Control& c : camera.controls) {
    if (c.id == id) return &c;
  }
  return nullptr;
}

// The value of control `id` (0 if the camera lacks it).
int32_t ControlValue(Camera& camera, uint32_t id) {
  const Control* c = FindControl(camera, id);
  return c == nullptr ? 0 : c->value;
}

// Whether `c` is inactive: its auto mode is on.
bool Inactive(Camera& camera, const Control& c) {
  return c.master != 0 && ControlValue(camera, c.master) != c.master_manual;
}

// Moves control `id` one bounded step towards `target` while `c` is inactive (its auto mode runs).
void Chase(Camera& camera, uint32_t id, int32_t target, int32_t step) {
  Control* c = FindControl(camera, id);
  if (c == nullptr || !Inactive(camera, *c)) return;
  c->value += std::clamp(target - c->value, -step, step);
  c->value = std::clamp(c->value, c->minimum, c->maximum);
}

// The auto modes at frame `tick`: the scene keeps changing (sawtooth brightness and colour), so
// values move every frame while their auto mode is on and only a lock freezes them.
void RunAutoModes(Camera& camera, uint64_t tick) {
  Chase(camera, V4L2_CID_EXPOSURE_ABSOLUTE, static_cast<int32_t>(200 + (tick * 3) % 200), 4);
  Chase(camera, V4L2_CID_WHITE_BALANCE_TEMPERATURE, static_cast<int32_t>(3000 + (tick * 20) % 2000),
        30);
  Chase(camera, V4L2_CID_GAIN, static_cast<int32_t>(16 + tick % 48), 2);
}

// "exposure=.. gain=.. wb=.." for the log.
std::string ControlSnapshot(Camera& camera) {
  return "exposure=" + std::to_string(ControlValue(camera, V4L2_CID_EXPOSURE_ABSOLUTE)) +
         " gain=" + std::to_string(ControlValue(camera, V4L2_CID_GAIN)) +
         " wb=" + std::to_string(ControlValue(camera, V4L2_CID_WHITE_BALANCE_TEMPERATURE));
}

// Applies a state change seen now (caller holds the mutex): unplug kills every open descriptor
// and resets the controls (the camera lost power); a state other than unplugged is a replug.
void Observe(Camera& camera, DeviceState state) {
  if (state == DeviceState::kUnplugged && !camera.unplugged) {
    camera.unplugged = true;
    Log("unplug");
    for (auto& [fd, h] : camera.handles) {
      h->dead = true;
      if (h->signal_fd >= 0) Next().close(h->signal_fd);  // poll() on fd: POLLHUP
      h->signal_fd = -1;
      h->wake.notify_all();
    }
    camera.controls = DefaultControls();
  } else if (state != DeviceState::kUnplugged && camera.unplugged) {
    camera.unplugged = false;
    Log("replug");
  }
}

// The formats the recordings offer, in ENUM_FMT order.
std::vector<uint32_t> OfferedFormats(const Config& config) {
  std::vector<uint32_t> f;
  if (!config.yuyv.empty()) f.push_back(V4L2_PIX_FMT_YUYV);
  if (!config.mjpeg.empty()) f.push_back(V4L2_PIX_FMT_MJPEG);
  return f;
}

// Whether the recordings offer `fourcc`.
bool Offered(const Config& config, uint32_t fourcc) {
  const std::vector<uint32_t> f = OfferedFormats(config);
  return std::find(f.begin(), f.end(), fourcc) != f.end();
}

// "YUYV" / "MJPG".
std::string FourccName(uint32_t fourcc) {
  std::string s(4, ' ');
  for (int i = 0; i < 4; ++i) s[i] = static_cast<char>((fourcc >> (8 * i)) & 0xFF);
  return s;
}

// Bytes of one buffer (sizeimage): a YUYV frame; MJPEG frames use part of it.
size_t SizeImage(const Config& config) {
  return static_cast<size_t>(config.width) * config.height * 2;
}

// One tick of the frame clock at `tick_ns` (caller holds the mutex): the auto modes step, and the
// oldest queued buffer receives the recording's next frame (damaged if the lists say so), or the
// frame is dropped.
void Tick(Camera& camera, const Config& config, Handle& h, int64_t tick_ns, int64_t period_ns) {
  const uint64_t sequence = h.ticks++;
  RunAutoModes(camera, sequence);
  const std::vector<std::string>& frames =
      h.fourcc == V4L2_PIX_FMT_MJPEG ? config.mjpeg : config.yuyv;
  const size_t source = sequence % frames.size();
  if (h.queued.empty()) {
    Log("drop handle=%d seq=%llu source=%zu", h.id, static_cast<unsigned long long>(sequence),
        source);
    return;
  }
  const uint32_t index = h.queued.front();
  h.queued.pop_front();
  Buffer& b = h.buffers[index];
  const std::string& frame = frames[source];
  const uint64_t served = h.served++;
  const bool corrupt = h.fourcc == V4L2_PIX_FMT_MJPEG && config.corrupt.Contains(served);
  const size_t bytes = corrupt ? std::min(kCorruptBytes, frame.size()) : frame.size();
  std::memcpy(h.memory + index * h.buffer_stride, frame.data(), bytes);
  b.bytesused = static_cast<uint32_t>(bytes);
  b.error = config.error_flag.Contains(served);
  b.sequence = static_cast<uint32_t>(sequence);
  b.timestamp_ns = (tick_ns - period_ns / 2) / 1000 * 1000;  // start of exposure, µs
  b.state = Buffer::State::kDone;
  h.done.push_back(index);
  [[maybe_unused]] const ssize_t written = ::write(h.signal_fd, "f", 1);
  h.wake.notify_all();
  Log("%s handle=%d seq=%llu served=%llu buffer=%u source=%zu bytes=%u ts_ns=%lld %s",
      b.error ? "flagged" : (corrupt ? "corrupt" : "frame"), h.id,
      static_cast<unsigned long long>(sequence), static_cast<unsigned long long>(served), index,
      source, b.bytesused, static_cast<long long>(b.timestamp_ns), ControlSnapshot(camera).c_str());
}

// The frame clock of a streaming descriptor: ticks at start + k periods, watches the state file
// every 5 ms, ends on STREAMOFF/close or unplug.
void RunClock(std::shared_ptr<Handle> h, int64_t start_ns) {
  Camera& camera = TheCamera();
  const Config& config = GetConfig();
  const int64_t period_ns = 1'000'000'000 / h->fps;
  int64_t next_ns = start_ns + period_ns;
  while (true) {
    const DeviceState state = ReadState(config);
    std::unique_lock lock(camera.mutex);
    Observe(camera, state);
    if (h->stop_clock || h->dead) return;
    const int64_t now = NowNs();
    if (now >= next_ns) {
      Tick(camera, config, *h, next_ns, period_ns);
      next_ns += period_ns;
      continue;
    }
    h->wake.wait_for(lock, std::chrono::nanoseconds(std::min<int64_t>(next_ns - now, 5'000'000)));
  }
}

// Stops the frame clock of `h` (caller holds `lock`, released while joining).
void StopClock(Handle& h, std::unique_lock<std::mutex>& lock) {
  h.stop_clock = true;
  h.wake.notify_all();
  std::thread clock = std::move(h.clock);
  if (!clock.joinable()) return;
  lock.unlock();
  clock.join();
  lock.lock();
}

// Returns every buffer to the caller and empties the pipe (streaming stopped).
void ResetQueues(Handle& h) {
  for (Buffer& b : h.buffers) b.state = Buffer::State::kDequeued;
  h.queued.clear();
  h.done.clear();
  char drain[64];
  while (::read(h.fd, drain, sizeof drain) > 0) {
  }
}

// Frees the buffers of `h` (this library's mapping and the memfd; the caller's mappings keep
// their pages until munmap, as with the kernel's).
void FreeBuffers(Camera& camera, Handle& h) {
  if (h.memory != nullptr) ::munmap(h.memory, h.buffer_stride * h.buffers.size());
  if (h.memfd >= 0) Next().close(h.memfd);
  h.memory = nullptr;
  h.memfd = -1;
  h.buffers.clear();
  h.queued.clear();
  h.done.clear();
  if (camera.streamer == &h) camera.streamer = nullptr;
}

// Fills `b` with buffer `index` of `h` (`length` bytes), as QUERYBUF and DQBUF return it.
void FillBuffer(const Handle& h, uint32_t index, size_t length, v4l2_buffer& b) {
  const Buffer& buffer = h.buffers[index];
  std::memset(&b, 0, sizeof b);
  b.index = index;
  b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  b.memory = V4L2_MEMORY_MMAP;
  b.bytesused = buffer.bytesused;
  b.field = V4L2_FIELD_NONE;
  b.sequence = buffer.sequence;
  b.timestamp.tv_sec = buffer.timestamp_ns / 1'000'000'000;
  b.timestamp.tv_usec = (buffer.timestamp_ns % 1'000'000'000) / 1000;
  b.flags = V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_SOE;
  if (buffer.error && buffer.state != Buffer::State::kQueued) b.flags |= V4L2_BUF_FLAG_ERROR;
  if (buffer.mapped > 0) b.flags |= V4L2_BUF_FLAG_MAPPED;
  if (buffer.state == Buffer::State::kQueued) b.flags |= V4L2_BUF_FLAG_QUEUED;
  if (buffer.state == Buffer::State::kDone) b.flags |= V4L2_BUF_FLAG_DONE;
  b.m.offset = static_cast<uint32_t>(index * h.buffer_stride);
  b.length = static_cast<uint32_t>(length);
}

// Copies `text` into a fixed-size V4L2 string field.
template <size_t N>
void SetString(uint8_t (&field)[N], const std::string& text) {
  std::memset(field, 0, N);
  std::memcpy(field, text.data(), std::min(N - 1, text.size()));
}

// The emulated ioctl `request` on `h` (caller holds `lock`): 0 or -errno.
int Dispatch(Camera& camera, const Config& config, Handle& h, unsigned long request, void* arg,
             DeviceState state, std::unique_lock<std::mutex>& lock) {
  if (h.dead) return -ENODEV;
  const bool busy = state == DeviceState::kBusy;
  const size_t size_image = SizeImage(config);
  switch (request) {
    case VIDIOC_QUERYCAP: {
      auto* cap = static_cast<v4l2_capability*>(arg);
      std::memset(cap, 0, sizeof *cap);
      SetString(cap->driver, "probeless_standin");
      SetString(cap->card, "probeless V4L2 stand-in");
      SetString(cap->bus_info, "usb-probeless-standin");
      cap->version = (6u << 16) | (1u << 8);
      cap->device_caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_STREAMING | V4L2_CAP_EXT_PIX_FORMAT;
      cap->capabilities = cap->device_caps | V4L2_CAP_DEVICE_CAPS;
      return 0;
    }
    case VIDIOC_ENUM_FMT: {
      auto* d = static_cast<v4l2_fmtdesc*>(arg);
      const std::vector<uint32_t> formats = OfferedFormats(config);
      if (d->type != V4L2_BUF_TYPE_VIDEO_CAPTURE || d->index >= formats.size()) return -EINVAL;
      const uint32_t index = d->index;
      std::memset(d, 0, sizeof *d);
      d->index = index;
      d->type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      d->pixelformat = formats[index];
      d->flags = formats[index] == V4L2_PIX_FMT_MJPEG ? V4L2_FMT_FLAG_COMPRESSED : 0;
      SetString(d->description,
                formats[index] == V4L2_PIX_FMT_MJPEG ? "Motion-JPEG" : "YUYV 4:2:2");
      return 0;
    }
    case VIDIOC_ENUM_FRAMESIZES: {
      auto* s = static_cast<v4l2_frmsizeenum*>(arg);
      if (!Offered(config, s->pixel_format) || s->index != 0) return -EINVAL;
      s->type = V4L2_FRMSIZE_TYPE_DISCRETE;
      s->discrete.width = config.width;
      s->discrete.height = config.height;
      return 0;
    }
    case VIDIOC_ENUM_FRAMEINTERVALS: {
      auto* i = static_cast<v4l2_frmivalenum*>(arg);
      if (!Offered(config, i->pixel_format) || i->width != config.width ||
          i->height != config.height || i->index > 1) {
        return -EINVAL;
      }
      i->type = V4L2_FRMIVAL_TYPE_DISCRETE;
      i->discrete.numerator = 1;
      i->discrete.denominator = i->index == 0 ? 30 : 15;
      return 0;
    }
    case VIDIOC_G_FMT:
    case VIDIOC_S_FMT:
    case VIDIOC_TRY_FMT: {
      auto* f = static_cast<v4l2_format*>(arg);
      if (f->type != V4L2_BUF_TYPE_VIDEO_CAPTURE) return -EINVAL;
      uint32_t fourcc = h.fourcc;
      if (request != VIDIOC_G_FMT) {
        if (request == VIDIOC_S_FMT && busy) return -EBUSY;
        if (request == VIDIOC_S_FMT && (h.streaming || !h.buffers.empty())) return -EBUSY;
        // Drivers adjust instead of failing: an unknown format becomes the first offered.
        fourcc = Offered(config, f->fmt.pix.pixelformat) ? f->fmt.pix.pixelformat
                                                         : OfferedFormats(config).front();
      }
      std::memset(&f->fmt, 0, sizeof f->fmt);
      v4l2_pix_format& p = f->fmt.pix;
      p.width = config.width;
      p.height = config.height;
      p.pixelformat = fourcc;
      p.field = V4L2_FIELD_NONE;
      p.bytesperline = fourcc == V4L2_PIX_FMT_YUYV ? config.width * 2 : 0;
      p.sizeimage = static_cast<uint32_t>(size_image);
      p.colorspace = V4L2_COLORSPACE_SRGB;
      if (request == VIDIOC_S_FMT) {
        h.fourcc = fourcc;
        Log("s_fmt handle=%d fourcc=%s size=%ux%u", h.id, FourccName(fourcc).c_str(), p.width,
            p.height);
      }
      return 0;
    }
    case VIDIOC_G_PARM:
    case VIDIOC_S_PARM: {
      auto* p = static_cast<v4l2_streamparm*>(arg);
      if (p->type != V4L2_BUF_TYPE_VIDEO_CAPTURE) return -EINVAL;
      if (request == VIDIOC_S_PARM) {
        if (busy || h.streaming) return -EBUSY;
        const v4l2_fract t = p->parm.capture.timeperframe;
        const double wanted =
            t.numerator == 0 ? 30.0 : static_cast<double>(t.denominator) / t.numerator;
        h.fps = std::abs(wanted - 30) <= std::abs(wanted - 15) ? 30 : 15;
        Log("s_parm handle=%d fps=%u", h.id, h.fps);
      }
      std::memset(&p->parm, 0, sizeof p->parm);
      p->parm.capture.capability = V4L2_CAP_TIMEPERFRAME;
      p->parm.capture.timeperframe = {1, h.fps};
      return 0;
    }
    case VIDIOC_REQBUFS: {
      auto* r = static_cast<v4l2_requestbuffers*>(arg);
      if (r->type != V4L2_BUF_TYPE_VIDEO_CAPTURE || r->memory != V4L2_MEMORY_MMAP) return -EINVAL;
      if (busy || (camera.streamer != nullptr && camera.streamer != &h)) return -EBUSY;
      if (h.streaming) return -EBUSY;
      for (const Buffer& b : h.buffers) {
        if (b.mapped > 0) return -EBUSY;  // vb2 refuses to free mapped buffers
      }
      FreeBuffers(camera, h);
      const uint32_t count = std::min(r->count, kMaxBuffers);
      r->count = count;
      r->capabilities = V4L2_BUF_CAP_SUPPORTS_MMAP;
      Log("reqbufs handle=%d count=%u", h.id, count);
      if (count == 0) return 0;
      const size_t page = static_cast<size_t>(sysconf(_SC_PAGESIZE));
      h.buffer_stride = (size_image + page - 1) / page * page;
      h.memfd = memfd_create("probeless-v4l2-standin", MFD_CLOEXEC);
      if (h.memfd < 0) return -ENOMEM;
      if (ftruncate(h.memfd, static_cast<off_t>(h.buffer_stride * count)) != 0) {
        FreeBuffers(camera, h);
        return -ENOMEM;
      }
      void* m =
          ::mmap(nullptr, h.buffer_stride * count, PROT_READ | PROT_WRITE, MAP_SHARED, h.memfd, 0);
      if (m == MAP_FAILED) {
        FreeBuffers(camera, h);
        return -ENOMEM;
      }
      h.memory = static_cast<uint8_t*>(m);
      h.buffers.assign(count, Buffer{});
      camera.streamer = &h;
      return 0;
    }
    case VIDIOC_QUERYBUF:
    case VIDIOC_QBUF: {
      auto* b = static_cast<v4l2_buffer*>(arg);
      if (b->type != V4L2_BUF_TYPE_VIDEO_CAPTURE || b->memory != V4L2_MEMORY_MMAP ||
          b->index >= h.buffers.size()) {
        return -EINVAL;
      }
      const uint32_t index = b->index;
      if (request == VIDIOC_QBUF) {
        if (h.buffers[index].state != Buffer::State::kDequeued) return -EINVAL;
        h.buffers[index].state = Buffer::State::kQueued;
        h.queued.push_back(index);
      }
      FillBuffer(h, index, size_image, *b);
      return 0;
    }
    case VIDIOC_DQBUF: {
      auto* b = static_cast<v4l2_buffer*>(arg);
      if (b->type != V4L2_BUF_TYPE_VIDEO_CAPTURE || b->memory != V4L2_MEMORY_MMAP) return -EINVAL;
      if (!h.streaming) return -EINVAL;
      while (h.done.empty()) {
        if (h.nonblocking) return -EAGAIN;
        h.wake.wait(lock);
        if (h.dead) return -ENODEV;
        if (!h.streaming) return -EINVAL;
      }
      const uint32_t index = h.done.front();
      h.done.pop_front();
      char signal = 0;
      [[maybe_unused]] const ssize_t n = ::read(h.fd, &signal, 1);
      FillBuffer(h, index, size_image, *b);
      h.buffers[index].state = Buffer::State::kDequeued;
      return 0;
    }
    case VIDIOC_STREAMON: {
      const auto* type = static_cast<const int*>(arg);
      if (*type != V4L2_BUF_TYPE_VIDEO_CAPTURE || h.buffers.empty()) return -EINVAL;
      if (h.streaming) return 0;
      h.streaming = true;
      h.stop_clock = false;
      h.ticks = 0;
      h.served = 0;
      std::shared_ptr<Handle> self = camera.handles.at(h.fd);
      const int64_t start = NowNs();
      h.clock = std::thread(RunClock, self, start);
      Log("streamon handle=%d fourcc=%s fps=%u buffers=%zu queued=%zu", h.id,
          FourccName(h.fourcc).c_str(), h.fps, h.buffers.size(), h.queued.size());
      return 0;
    }
    case VIDIOC_STREAMOFF: {
      const auto* type = static_cast<const int*>(arg);
      if (*type != V4L2_BUF_TYPE_VIDEO_CAPTURE) return -EINVAL;
      StopClock(h, lock);
      if (h.streaming) Log("streamoff handle=%d", h.id);
      h.streaming = false;
      ResetQueues(h);
      return 0;
    }
    case VIDIOC_QUERYCTRL: {
      auto* q = static_cast<v4l2_queryctrl*>(arg);
      const bool next = (q->id & V4L2_CTRL_FLAG_NEXT_CTRL) != 0;
      const uint32_t id = q->id & ~(V4L2_CTRL_FLAG_NEXT_CTRL | V4L2_CTRL_FLAG_NEXT_COMPOUND);
      const Control* c = nullptr;
      for (const Control& k : camera.controls) {
        if (next ? k.id > id : k.id == id) {
          c = &k;
          break;
        }
      }
      if (c == nullptr) return -EINVAL;
      std::memset(q, 0, sizeof *q);
      q->id = c->id;
      q->type = c->type;
      SetString(q->name, c->name);
      q->minimum = c->minimum;
      q->maximum = c->maximum;
      q->step = c->step;
      q->default_value = c->default_value;
      q->flags = Inactive(camera, *c) ? V4L2_CTRL_FLAG_INACTIVE : 0;
      return 0;
    }
    case VIDIOC_G_CTRL: {
      auto* v = static_cast<v4l2_control*>(arg);
      const Control* c = FindControl(camera, v->id);
      if (c == nullptr) return -EINVAL;
      v->value = c->value;
      Log("g_ctrl handle=%d name=%s value=%d", h.id, c->name, c->value);
      return 0;
    }
    case VIDIOC_S_CTRL: {
      auto* v = static_cast<v4l2_control*>(arg);
      Control* c = FindControl(camera, v->id);
      int result = 0;
      int32_t value = v->value;
      if (c == nullptr) {
        result = -EINVAL;
      } else if (Inactive(camera, *c)) {
        result = -EACCES;
      } else if (c->type == V4L2_CTRL_TYPE_BOOLEAN) {
        value = value != 0;
      } else if (c->type == V4L2_CTRL_TYPE_MENU) {
        if (value < c->minimum || value > c->maximum || !(c->menu_mask & (1u << value))) {
          result = -EINVAL;
        }
      } else {
        value = std::clamp(value, c->minimum, c->maximum);
        value = c->minimum + (value - c->minimum) / c->step * c->step;
      }
      if (result == 0) {
        c->value = value;
        v->value = value;
      }
      char unknown[16];
      std::snprintf(unknown, sizeof unknown, "0x%x", v->id);
      Log("s_ctrl handle=%d name=%s value=%d result=%s %s", h.id, c == nullptr ? unknown : c->name,
          value, result == 0 ? "ok" : (result == -EACCES ? "EACCES" : "EINVAL"),
          ControlSnapshot(camera).c_str());
      return result;
    }
    default:
      if (camera.reported_requests.insert(request).second) {
        std::fprintf(stderr, "[warn] [v4l2_standin] ioctl 0x%lx is not emulated (ENOTTY)\n",
                     request);
      }
      return -ENOTTY;
  }
}

// ioctl on `fd` if it is the device's (true, result in `result`), else false.
bool EmulatedIoctl(int fd, unsigned long request, void* arg, int& result) {
  if (DevicePath().empty()) return false;
  Camera& camera = TheCamera();
  {
    std::lock_guard lock(camera.mutex);
    if (!camera.handles.contains(fd)) return false;
  }
  const Config& config = GetConfig();
  const DeviceState state = ReadState(config);
  std::unique_lock lock(camera.mutex);
  Observe(camera, state);
  const auto it = camera.handles.find(fd);
  if (it == camera.handles.end()) {
    result = -1;
    errno = EBADF;
    return true;
  }
  std::shared_ptr<Handle> h = it->second;
  const int r = Dispatch(camera, config, *h, request, arg, state, lock);
  result = r < 0 ? -1 : r;
  if (r < 0) errno = -r;
  return true;
}

// Opens the device (`path` is DevicePath()): a new descriptor, or -1 with errno.
int OpenDevice(int flags) {
  const Config& config = GetConfig();
  if (!config.error.empty()) {
    PrintError(config.error);
    errno = EINVAL;
    return -1;
  }
  const DeviceState state = ReadState(config);
  Camera& camera = TheCamera();
  std::lock_guard lock(camera.mutex);
  Observe(camera, state);
  if (state == DeviceState::kUnplugged) {
    Log("open-failed errno=ENOENT");
    errno = ENOENT;
    return -1;
  }
  int pipe_fds[2];
  if (pipe2(pipe_fds, O_CLOEXEC | O_NONBLOCK) != 0) return -1;
  auto h = std::make_shared<Handle>();
  h->id = ++camera.opens;
  h->fd = pipe_fds[0];
  h->signal_fd = pipe_fds[1];
  h->nonblocking = (flags & O_NONBLOCK) != 0;
  h->fourcc = OfferedFormats(config).front();
  camera.handles[h->fd] = h;
  Log("open handle=%d fd=%d", h->id, h->fd);
  return h->fd;
}

// Closes `fd` if it is the device's (true, result in `result`), else false.
bool CloseDevice(int fd, int& result) {
  if (DevicePath().empty()) return false;
  Camera& camera = TheCamera();
  std::unique_lock lock(camera.mutex);
  const auto it = camera.handles.find(fd);
  if (it == camera.handles.end()) return false;
  std::shared_ptr<Handle> h = it->second;
  StopClock(*h, lock);
  FreeBuffers(camera, *h);
  if (h->signal_fd >= 0) Next().close(h->signal_fd);
  h->signal_fd = -1;
  camera.handles.erase(h->fd);
  Log("close handle=%d %s", h->id, ControlSnapshot(camera).c_str());
  result = Next().close(h->fd);
  return true;
}

// Whether `path` names the emulated device.
bool IsDevice(const char* path) {
  return path != nullptr && !DevicePath().empty() && DevicePath() == path;
}

// The mode argument of open(), present with O_CREAT or O_TMPFILE.
mode_t ModeOf(int flags, va_list args) {
  return (flags & O_CREAT) || (flags & O_TMPFILE) == O_TMPFILE ? va_arg(args, mode_t) : 0;
}

// Reports at exit what a process that opened the device left open (descriptors, mappings), so
// a test can fail a node that leaks them.
__attribute__((destructor)) void ReportAtExit() {
  if (DevicePath().empty()) return;
  Camera& camera = TheCamera();
  std::lock_guard lock(camera.mutex);
  if (camera.opens == 0) return;
  Log("exit open=%zu mappings=%zu", camera.handles.size(), camera.mappings.size());
}

}  // namespace

// --- The interposed entry points ------------------------------------------------------------

extern "C" {

// libc open: the device path opens the emulated device, others the real file.
int open(const char* path, int flags, ...) {
  va_list args;
  va_start(args, flags);
  const mode_t mode = ModeOf(flags, args);
  va_end(args);
  if (IsDevice(path)) return OpenDevice(flags);
  return Next().open(path, flags, mode);
}

// libc open64: as open.
int open64(const char* path, int flags, ...) {
  va_list args;
  va_start(args, flags);
  const mode_t mode = ModeOf(flags, args);
  va_end(args);
  if (IsDevice(path)) return OpenDevice(flags);
  return Next().open64(path, flags, mode);
}

// glibc's fortified open: as open.
int __open_2(const char* path, int flags) {
  if (IsDevice(path)) return OpenDevice(flags);
  return Next().open_2(path, flags);
}

// glibc's fortified open64: as open.
int __open64_2(const char* path, int flags) {
  if (IsDevice(path)) return OpenDevice(flags);
  return Next().open64_2(path, flags);
}

// libc close: releases an emulated descriptor (stops its clock, frees its buffers).
int close(int fd) {
  int result = 0;
  if (CloseDevice(fd, result)) return result;
  return Next().close(fd);
}

// libc ioctl: emulated on the device's descriptors (the node's raw VIDIOC_QUERYCAP probe).
int ioctl(int fd, unsigned long request, ...) noexcept {
  va_list args;
  va_start(args, request);
  void* arg = va_arg(args, void*);
  va_end(args);
  int result = 0;
  if (EmulatedIoctl(fd, request, arg, result)) return result;
  return Next().ioctl(fd, request, arg);
}

// libv4l2 v4l2_fd_open: an emulated descriptor is used as it is.
int v4l2_fd_open(int fd, int v4l2_flags) {
  if (!DevicePath().empty()) {
    Camera& camera = TheCamera();
    std::lock_guard lock(camera.mutex);
    if (const auto it = camera.handles.find(fd); it != camera.handles.end()) {
      Log("v4l2_fd_open handle=%d flags=0x%x", it->second->id, v4l2_flags);
      return fd;  // libv4l2's own wrapper is bypassed: no conversion, as the node asks
    }
  }
  if (Next().v4l2_fd_open == nullptr) {
    errno = ENOSYS;
    return -1;
  }
  return Next().v4l2_fd_open(fd, v4l2_flags);
}

// libv4l2 v4l2_close: as close for emulated descriptors.
int v4l2_close(int fd) {
  int result = 0;
  if (CloseDevice(fd, result)) return result;
  if (Next().v4l2_close == nullptr) return Next().close(fd);
  return Next().v4l2_close(fd);
}

// libv4l2 v4l2_ioctl: emulated on the device's descriptors.
int v4l2_ioctl(int fd, unsigned long int request, ...) {
  va_list args;
  va_start(args, request);
  void* arg = va_arg(args, void*);
  va_end(args);
  int result = 0;
  if (EmulatedIoctl(fd, request, arg, result)) return result;
  if (Next().v4l2_ioctl == nullptr) return Next().ioctl(fd, request, arg);
  return Next().v4l2_ioctl(fd, request, arg);
}

// libv4l2 v4l2_mmap: maps buffer `offset` / QUERYBUF's m.offset of an emulated descriptor.
void* v4l2_mmap(void* start, size_t length, int prot, int flags, int fd, int64_t offset) {
  if (!DevicePath().empty()) {
    Camera& camera = TheCamera();
    std::lock_guard lock(camera.mutex);
    if (const auto it = camera.handles.find(fd); it != camera.handles.end()) {
      Handle& h = *it->second;
      if (h.dead) {
        errno = ENODEV;
        return MAP_FAILED;
      }
      const size_t size_image = SizeImage(GetConfig());
      if (h.buffer_stride == 0 || offset < 0 || offset % h.buffer_stride != 0 ||
          static_cast<size_t>(offset) / h.buffer_stride >= h.buffers.size() ||
          length > size_image || length == 0) {
        errno = EINVAL;
        return MAP_FAILED;
      }
      void* p = ::mmap(start, length, prot, flags, h.memfd, offset);
      if (p == MAP_FAILED) return p;
      const auto index = static_cast<uint32_t>(offset / h.buffer_stride);
      ++h.buffers[index].mapped;
      camera.mappings[p] = Mapping{it->second, index};
      return p;
    }
  }
  if (Next().v4l2_mmap == nullptr) {
    errno = ENOSYS;
    return MAP_FAILED;
  }
  return Next().v4l2_mmap(start, length, prot, flags, fd, offset);
}

// libv4l2 v4l2_munmap: unmaps what v4l2_mmap mapped of an emulated descriptor.
int v4l2_munmap(void* start, size_t length) {
  if (!DevicePath().empty()) {
    Camera& camera = TheCamera();
    std::lock_guard lock(camera.mutex);
    if (const auto it = camera.mappings.find(start); it != camera.mappings.end()) {
      if (std::shared_ptr<Handle> h = it->second.handle.lock()) {
        if (it->second.index < h->buffers.size() && h->buffers[it->second.index].mapped > 0) {
          --h->buffers[it->second.index].mapped;
        }
      }
      camera.mappings.erase(it);
      return ::munmap(start, length);
    }
  }
  if (Next().v4l2_munmap == nullptr) return ::munmap(start, length);
  return Next().v4l2_munmap(start, length);
}

}  // extern "C"
