// bus_bench transport: a Unix domain stream socket per subscriber (a copy transport).
//
// Frames are an 8-byte length followed by the payload. The publisher never blocks: it sends with
// MSG_DONTWAIT, keeps the unsent rest of a frame (one per subscriber, no copy: the loan buffer
// stays referenced) and moves it on in Pump(); a subscriber whose previous frame is still pending
// misses the new message (drop-newest, counted by the publisher: TransportDrops()).
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <stdexcept>
#include <vector>

#include "channel.h"

namespace probeless::bus_bench {
namespace {

constexpr size_t kPayloadOffset = 64;  // the length prefix sits just before the payload
constexpr size_t kLengthBytes = sizeof(uint64_t);
constexpr int kSocketBufferBytes = 8 << 20;  // requested; the kernel caps it (net.core.*mem_max)

int64_t NowNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

[[noreturn]] void Fail(const std::string& what) {
  throw std::runtime_error("uds: " + what + ": " + std::strerror(errno));
}

sockaddr_un Address(const TopicId& id, socklen_t* length) {
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  // Abstract namespace: nothing is left in the file system.
  const std::string name = "bus_bench." + id.run_id + "." + std::to_string(id.publisher) + "." +
                           std::to_string(id.topic);
  std::memcpy(addr.sun_path + 1, name.data(), name.size());
  *length = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + 1 + name.size());
  return addr;
}

struct AlignedBuffer {
  explicit AlignedBuffer(size_t bytes)
      : data(static_cast<std::byte*>(std::aligned_alloc(64, (bytes + 63) / 64 * 64))) {
    if (data == nullptr) throw std::runtime_error("uds: out of memory");
  }
  ~AlignedBuffer() { std::free(data); }
  AlignedBuffer(const AlignedBuffer&) = delete;
  AlignedBuffer& operator=(const AlignedBuffer&) = delete;
  std::byte* data;
};

class UdsPub final : public PubChannel {
 public:
  UdsPub(const TopicId& id, size_t max_bytes, uint32_t subscribers) {
    listen_fd_ = socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (listen_fd_ < 0) Fail("socket");
    socklen_t length = 0;
    const sockaddr_un addr = Address(id, &length);
    if (bind(listen_fd_, reinterpret_cast<const sockaddr*>(&addr), length) != 0) Fail("bind");
    if (listen(listen_fd_, 64) != 0) Fail("listen");
    // Every subscriber pins at most one pending buffer; two more are always free for loans.
    for (uint32_t i = 0; i < subscribers + 2; ++i) {
      buffers_.push_back(std::make_unique<AlignedBuffer>(kPayloadOffset + max_bytes));
    }
    max_bytes_ = max_bytes;
  }

  ~UdsPub() override {
    for (Conn& c : conns_) close(c.fd);
    close(listen_fd_);
  }

  std::byte* Loan(size_t bytes) override {
    if (bytes > max_bytes_) throw std::runtime_error("uds: message larger than max_bytes");
    for (size_t b = 0; b < buffers_.size(); ++b) {
      bool pinned = false;
      for (const Conn& c : conns_) pinned |= c.buffer == static_cast<int>(b);
      if (pinned) continue;
      current_ = static_cast<int>(b);
      current_bytes_ = bytes;
      const uint64_t length = bytes;
      std::memcpy(buffers_[b]->data + kPayloadOffset - kLengthBytes, &length, kLengthBytes);
      return buffers_[b]->data + kPayloadOffset;
    }
    throw std::runtime_error("uds: every send buffer is pinned by a pending frame");
  }

  void Publish() override {
    const std::byte* frame = buffers_[current_]->data + kPayloadOffset - kLengthBytes;
    const size_t frame_bytes = kLengthBytes + current_bytes_;
    for (Conn& c : conns_) {
      Flush(c);
      if (c.buffer >= 0) {  // still sending an older frame: this subscriber misses one
        ++skipped_;
        continue;
      }
      const ssize_t n = send(c.fd, frame, frame_bytes, MSG_DONTWAIT | MSG_NOSIGNAL);
      if (n < 0 && errno != EAGAIN) Fail("send");
      const size_t sent = n < 0 ? 0 : static_cast<size_t>(n);
      if (sent < frame_bytes) {
        c.buffer = current_;
        c.offset = sent;
        c.length = frame_bytes;
      }
    }
    current_ = -1;
  }

  int64_t TransportDrops() const override { return skipped_; }

  uint32_t Subscribers(uint32_t) override {
    for (;;) {
      const int fd = accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd < 0) {
        if (errno == EAGAIN || errno == EINTR) break;
        Fail("accept");
      }
      const int bytes = kSocketBufferBytes;
      setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &bytes, sizeof(bytes));
      conns_.push_back(Conn{fd});
    }
    return static_cast<uint32_t>(conns_.size());
  }

  bool Pump(int64_t deadline_ns, bool spin) override {
    std::vector<pollfd> fds;
    for (;;) {
      fds.clear();
      for (Conn& c : conns_) {
        Flush(c);
        if (c.buffer >= 0) fds.push_back({c.fd, POLLOUT, 0});
      }
      if (fds.empty()) return false;
      const int64_t left = deadline_ns - NowNs();
      if (left <= 0) return true;
      if (spin) continue;
      const timespec timeout{left / 1'000'000'000, left % 1'000'000'000};
      if (ppoll(fds.data(), fds.size(), &timeout, nullptr) < 0 && errno != EINTR) Fail("ppoll");
    }
  }

 private:
  struct Conn {
    int fd = -1;
    int buffer = -1;  // pending frame's buffer, -1 if none
    size_t offset = 0;
    size_t length = 0;
  };

  void Flush(Conn& c) {
    while (c.buffer >= 0) {
      const std::byte* frame = buffers_[c.buffer]->data + kPayloadOffset - kLengthBytes;
      const ssize_t n =
          send(c.fd, frame + c.offset, c.length - c.offset, MSG_DONTWAIT | MSG_NOSIGNAL);
      if (n < 0) {
        if (errno == EAGAIN) return;
        Fail("send");
      }
      c.offset += static_cast<size_t>(n);
      if (c.offset == c.length) c.buffer = -1;
    }
  }

  int listen_fd_ = -1;
  size_t max_bytes_ = 0;
  std::vector<std::unique_ptr<AlignedBuffer>> buffers_;
  std::vector<Conn> conns_;
  int current_ = -1;
  size_t current_bytes_ = 0;
  int64_t skipped_ = 0;  // messages not sent to a subscriber whose previous frame was pending
};

class UdsSub final : public SubChannel {
 public:
  UdsSub(const TopicId& id, size_t max_bytes)
      : id_(id), buffer_(max_bytes), max_bytes_(max_bytes) {}
  ~UdsSub() override {
    if (fd_ >= 0) close(fd_);
  }

  bool Connected() override {
    if (connected_) return true;
    if (fd_ < 0) {
      fd_ = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
      if (fd_ < 0) Fail("socket");
    }
    socklen_t length = 0;
    const sockaddr_un addr = Address(id_, &length);
    if (connect(fd_, reinterpret_cast<const sockaddr*>(&addr), length) != 0) {
      if (errno != ECONNREFUSED && errno != ENOENT && errno != EAGAIN) Fail("connect");
      close(fd_);  // retry later with a fresh socket
      fd_ = -1;
      return false;
    }
    const int bytes = kSocketBufferBytes;
    setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &bytes, sizeof(bytes));
    const timeval stall{2, 0};  // a frame that stops mid-way for 2 s is an error
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &stall, sizeof(stall));
    connected_ = true;
    return true;
  }

  std::span<const std::byte> Receive(bool block, int64_t timeout_ns) override {
    if (block) {
      if (got_ == 0) {
        pollfd pfd{fd_, POLLIN, 0};
        const timespec timeout{timeout_ns / 1'000'000'000, timeout_ns % 1'000'000'000};
        const int rc = ppoll(&pfd, 1, &timeout, nullptr);
        if (rc < 0 && errno != EINTR) Fail("ppoll");
        if (rc <= 0) return {};
      }
      while (!Step(MSG_WAITALL)) {
      }
    } else {
      while (!Step(MSG_DONTWAIT)) {
        if (would_block_) return {};
      }
    }
    got_ = 0;
    return {buffer_.data, static_cast<size_t>(length_)};
  }

  void Release() override {}
  bool InMessage() const override { return got_ != 0; }

 private:
  // Reads more of the current frame; true once it is complete.
  bool Step(int flags) {
    would_block_ = false;
    std::byte* dst = nullptr;
    size_t want = 0;
    if (got_ < kLengthBytes) {
      dst = reinterpret_cast<std::byte*>(&length_) + got_;
      want = kLengthBytes - got_;
    } else {
      dst = buffer_.data + (got_ - kLengthBytes);
      want = kLengthBytes + length_ - got_;
    }
    const ssize_t n = recv(fd_, dst, want, flags);
    if (n < 0) {
      if (errno == EINTR) return false;
      if (errno == EAGAIN) {
        if (flags & MSG_DONTWAIT) {
          would_block_ = true;
          return false;
        }
        throw std::runtime_error("uds: a frame stalled for 2 s mid-way");
      }
      Fail("recv");
    }
    if (n == 0) throw std::runtime_error("uds: the publisher closed the connection");
    got_ += static_cast<size_t>(n);
    if (got_ == kLengthBytes && length_ > max_bytes_) {
      throw std::runtime_error("uds: frame of " + std::to_string(length_) +
                               " bytes exceeds max_bytes");
    }
    return got_ >= kLengthBytes && got_ == kLengthBytes + length_;
  }

  TopicId id_;
  AlignedBuffer buffer_;
  size_t max_bytes_;
  int fd_ = -1;
  bool connected_ = false;
  bool would_block_ = false;
  size_t got_ = 0;
  uint64_t length_ = 0;
};

}  // namespace

std::unique_ptr<PubChannel> MakeUdsPub(const TopicId& id, size_t max_bytes, uint32_t subscribers) {
  return std::make_unique<UdsPub>(id, max_bytes, subscribers);
}

std::unique_ptr<SubChannel> MakeUdsSub(const TopicId& id, size_t max_bytes) {
  return std::make_unique<UdsSub>(id, max_bytes);
}

}  // namespace probeless::bus_bench
