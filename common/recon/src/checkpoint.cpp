#include "probeless/recon/checkpoint.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "probeless/recon/math.h"

namespace probeless::recon {

namespace {

[[noreturn]] void Fail(const std::string& path, const std::string& step, int error) {
  throw ReconError("checkpoint '" + path + "': cannot " + step + ": " + std::strerror(error));
}

// Closes the descriptor on every path out.
struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

}  // namespace

void WriteFileAtomically(const std::string& path, std::span<const std::byte> bytes) {
  const std::string tmp = path + ".tmp";
  {
    Fd f{::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644)};
    if (f.fd < 0) Fail(path, "create " + tmp, errno);
    size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::write(f.fd, bytes.data() + done, bytes.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) {
        const int e = errno;
        ::unlink(tmp.c_str());
        Fail(path, "write " + tmp, e);
      }
      done += static_cast<size_t>(n);
    }
    if (::fsync(f.fd) != 0) {
      const int e = errno;
      ::unlink(tmp.c_str());
      Fail(path, "fsync " + tmp, e);
    }
    const int fd = f.fd;
    f.fd = -1;
    if (::close(fd) != 0) {
      const int e = errno;
      ::unlink(tmp.c_str());
      Fail(path, "close " + tmp, e);
    }
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int e = errno;
    ::unlink(tmp.c_str());
    Fail(path, "rename " + tmp + " over it", e);
  }
  // The rename itself reaches the disk with the directory.
  std::string dir = std::filesystem::path(path).parent_path().string();
  if (dir.empty()) dir = ".";
  Fd d{::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC)};
  if (d.fd < 0) Fail(path, "open its directory", errno);
  if (::fsync(d.fd) != 0) Fail(path, "fsync its directory", errno);
}

std::optional<std::vector<std::byte>> ReadFileIfExists(const std::string& path) {
  Fd f{::open(path.c_str(), O_RDONLY | O_CLOEXEC)};
  if (f.fd < 0) {
    if (errno == ENOENT) return std::nullopt;
    Fail(path, "read", errno);
  }
  struct stat st;
  if (::fstat(f.fd, &st) != 0) Fail(path, "read", errno);
  if (!S_ISREG(st.st_mode)) Fail(path, "read", EISDIR);
  std::vector<std::byte> bytes(static_cast<size_t>(st.st_size));
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::read(f.fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) Fail(path, "read", errno);
    if (n == 0) break;  // shrank meanwhile: the checksum will tell
    done += static_cast<size_t>(n);
  }
  bytes.resize(done);
  return bytes;
}

CheckpointWriter::CheckpointWriter(std::string path)
    : path_(std::move(path)), thread_([this] { Run(); }) {}

CheckpointWriter::~CheckpointWriter() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void CheckpointWriter::RethrowLocked() {
  if (error_) {
    std::exception_ptr e = error_;
    error_ = nullptr;
    std::rethrow_exception(e);
  }
}

void CheckpointWriter::Submit(std::vector<std::byte> bytes) {
  std::lock_guard<std::mutex> lock(mutex_);
  RethrowLocked();
  if (bytes.empty()) return;
  pending_ = std::move(bytes);
  wake_.notify_all();
}

void CheckpointWriter::Flush() {
  std::unique_lock<std::mutex> lock(mutex_);
  idle_.wait(lock, [&] { return !pending_ && !busy_; });
  RethrowLocked();
}

void CheckpointWriter::Discard() {
  std::unique_lock<std::mutex> lock(mutex_);
  pending_.reset();
  idle_.wait(lock, [&] { return !busy_; });
  error_ = nullptr;  // of a checkpoint that is discarded anyway
  if (::unlink(path_.c_str()) != 0 && errno != ENOENT) Fail(path_, "remove", errno);
}

uint64_t CheckpointWriter::written() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return written_;
}

void CheckpointWriter::Run() {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_.wait(lock, [&] { return stop_ || pending_; });
    if (!pending_) return;  // stop with nothing left
    std::vector<std::byte> bytes = std::move(*pending_);
    pending_.reset();
    busy_ = true;
    lock.unlock();
    std::exception_ptr error;
    try {
      WriteFileAtomically(path_, bytes);
    } catch (...) {
      error = std::current_exception();
    }
    lock.lock();
    busy_ = false;
    if (error) {
      error_ = error;
    } else {
      ++written_;
    }
    idle_.notify_all();
  }
}

}  // namespace probeless::recon
