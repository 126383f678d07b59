#include "shm.h"

#include <errno.h>
#include <fcntl.h>
#include <linux/futex.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <vector>

#include "probeless/error/error.h"

namespace probeless::bus::internal {
namespace {

std::string ErrnoText(int err) { return std::strerror(err); }

}  // namespace

std::string SegmentPrefix(const std::string& domain) {
  return "probeless." + std::to_string(::getuid()) + "." + domain + ".";
}

std::string EncodeTopic(std::string_view topic) {
  std::string out(topic.substr(topic.empty() ? 0 : 1));
  for (char& c : out) {
    if (c == '/') c = '.';
  }
  return out;
}

std::string DecodeTopic(std::string_view encoded) {
  std::string out = "/";
  out += encoded;
  for (char& c : out) {
    if (c == '.') c = '/';
  }
  return out;
}

std::string TopicSegmentName(const std::string& domain, std::string_view topic) {
  return SegmentPrefix(domain) + "t." + EncodeTopic(topic);
}

Mapping::~Mapping() {
  if (base_ != nullptr) ::munmap(base_, bytes_);
}

std::shared_ptr<Mapping> CreateSegment(const std::string& name, size_t bytes) {
  const std::string path = "/" + name;
  int fd = ::shm_open(path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0) {
    if (errno == EEXIST) return nullptr;
    throw BusError("cannot create shared memory segment '" + name + "': " + ErrnoText(errno));
  }
  // The mode given to shm_open is filtered by the umask; make it exactly owner read/write.
  ::fchmod(fd, 0600);
  if (::ftruncate(fd, static_cast<off_t>(bytes)) != 0) {
    const int err = errno;
    ::close(fd);
    ::shm_unlink(path.c_str());
    throw BusError("cannot size shared memory segment '" + name + "' to " + std::to_string(bytes) +
                   " bytes: " + ErrnoText(err));
  }
  void* base = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  const int err = errno;
  ::close(fd);
  if (base == MAP_FAILED) {
    ::shm_unlink(path.c_str());
    throw BusError("cannot map shared memory segment '" + name + "': " + ErrnoText(err));
  }
  return std::make_shared<Mapping>(base, bytes);
}

std::shared_ptr<Mapping> OpenSegment(const std::string& name, size_t min_bytes) {
  const std::string path = "/" + name;
  int fd = ::shm_open(path.c_str(), O_RDWR | O_CLOEXEC, 0);
  if (fd < 0) {
    if (errno == ENOENT) return nullptr;
    throw BusError("cannot open shared memory segment '" + name + "': " + ErrnoText(errno));
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    throw BusError("cannot stat shared memory segment '" + name + "': " + ErrnoText(err));
  }
  if (st.st_uid != ::getuid()) {
    ::close(fd);
    throw BusError("shared memory segment '" + name + "' belongs to another user (uid " +
                   std::to_string(st.st_uid) + ")");
  }
  const size_t bytes = static_cast<size_t>(st.st_size);
  if (bytes == 0 || bytes < min_bytes) {
    ::close(fd);
    return nullptr;  // its creator has not sized it yet
  }
  void* base = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  const int err = errno;
  ::close(fd);
  if (base == MAP_FAILED) {
    throw BusError("cannot map shared memory segment '" + name + "': " + ErrnoText(err));
  }
  return std::make_shared<Mapping>(base, bytes);
}

void UnlinkSegment(const std::string& name) { ::shm_unlink(("/" + name).c_str()); }

uint64_t ProcessStartTime(int32_t pid) {
  char path[64];
  std::snprintf(path, sizeof(path), "/proc/%d/stat", pid);
  int fd = ::open(path, O_RDONLY | O_CLOEXEC);
  if (fd < 0) return 0;
  char buf[1024];
  const ssize_t n = ::read(fd, buf, sizeof(buf) - 1);
  ::close(fd);
  if (n <= 0) return 0;
  buf[n] = '\0';
  // The command name (field 2) may contain spaces and parentheses: parse after the last ')'.
  const char* p = std::strrchr(buf, ')');
  if (p == nullptr) return 0;
  p += 2;  // ") " -> field 3 (state)
  if (*p == 'Z' || *p == 'X') return 0;
  // Fields 3..21 precede the start time (field 22).
  for (int field = 3; field < 22; ++field) {
    p = std::strchr(p, ' ');
    if (p == nullptr) return 0;
    ++p;
  }
  return std::strtoull(p, nullptr, 10);
}

const ProcessId& Self() {
  static const ProcessId self = [] {
    ProcessId id;
    id.pid = static_cast<int32_t>(::getpid());
    id.start_time = ProcessStartTime(id.pid);
    return id;
  }();
  // After fork() the cached identity belongs to the parent: recompute for the child.
  thread_local ProcessId forked;
  if (self.pid != ::getpid()) {
    if (forked.pid != ::getpid()) {
      forked.pid = static_cast<int32_t>(::getpid());
      forked.start_time = ProcessStartTime(forked.pid);
    }
    return forked;
  }
  return self;
}

bool ProbablyAlive(const ProcessId& id) {
  if (id.pid <= 0) return false;
  return !(::kill(id.pid, 0) != 0 && errno == ESRCH);
}

bool DefinitelyAlive(const ProcessId& id) {
  if (!ProbablyAlive(id)) return false;
  const uint64_t start = ProcessStartTime(id.pid);
  return start != 0 && start == id.start_time;
}

void InitRobustMutex(pthread_mutex_t* mutex) {
  pthread_mutexattr_t attr;
  pthread_mutexattr_init(&attr);
  pthread_mutexattr_setpshared(&attr, PTHREAD_PROCESS_SHARED);
  pthread_mutexattr_setrobust(&attr, PTHREAD_MUTEX_ROBUST);
  const int rc = pthread_mutex_init(mutex, &attr);
  pthread_mutexattr_destroy(&attr);
  PROBELESS_DEMAND(rc == 0, "pthread_mutex_init of a robust shared mutex failed");
}

RobustLock::RobustLock(pthread_mutex_t* mutex) : mutex_(mutex) {
  const int rc = pthread_mutex_lock(mutex_);
  if (rc == EOWNERDEAD) {
    pthread_mutex_consistent(mutex_);
    recovered_ = true;
  } else if (rc != 0) {
    throw BusError(std::string("cannot lock a bus mutex in shared memory: ") + ErrnoText(rc));
  }
}

RobustLock::~RobustLock() { pthread_mutex_unlock(mutex_); }

void FutexWakeAll(std::atomic<uint32_t>* word) {
  ::syscall(SYS_futex, reinterpret_cast<uint32_t*>(word), FUTEX_WAKE, INT32_MAX, nullptr, nullptr,
            0);
}

void FutexWait(std::atomic<uint32_t>* word, uint32_t expected, int64_t deadline_mono_ns) {
  const int64_t now = MonotonicNowNs();
  if (deadline_mono_ns <= now) return;
  // FUTEX_WAIT_BITSET takes an absolute CLOCK_MONOTONIC deadline.
  timespec deadline{};
  deadline.tv_sec = deadline_mono_ns / 1'000'000'000;
  deadline.tv_nsec = deadline_mono_ns % 1'000'000'000;
  ::syscall(SYS_futex, reinterpret_cast<uint32_t*>(word), FUTEX_WAIT_BITSET, expected, &deadline,
            nullptr, FUTEX_BITSET_MATCH_ANY);
}

void FutexWaitMany(std::atomic<uint32_t>* const* words, const uint32_t* expected, size_t count,
                   int64_t deadline_mono_ns) {
  if (count == 0 || deadline_mono_ns <= MonotonicNowNs()) return;
  if (count == 1) return FutexWait(words[0], expected[0], deadline_mono_ns);
  std::vector<futex_waitv> waiters(count);
  for (size_t i = 0; i < count; ++i) {
    waiters[i] = {};
    waiters[i].val = expected[i];
    waiters[i].uaddr = reinterpret_cast<uintptr_t>(words[i]);
    waiters[i].flags = FUTEX_32;  // shared: no FUTEX_PRIVATE_FLAG
  }
  timespec deadline{};
  deadline.tv_sec = deadline_mono_ns / 1'000'000'000;
  deadline.tv_nsec = deadline_mono_ns % 1'000'000'000;
  const long rc = ::syscall(SYS_futex_waitv, waiters.data(), static_cast<unsigned>(count), 0,
                            &deadline, CLOCK_MONOTONIC);
  if (rc < 0 && errno == ENOSYS) {
    // Kernels before 5.16: wait on the first word in short slices so the others are seen too.
    const int64_t slice = std::min<int64_t>(deadline_mono_ns, MonotonicNowNs() + 1'000'000);
    FutexWait(words[0], expected[0], slice);
  }
}

int64_t MonotonicNowNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

int64_t WallNowNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

void CopyText(char* field, size_t field_bytes, std::string_view text) {
  const size_t n = std::min(text.size(), field_bytes - 1);
  std::memcpy(field, text.data(), n);
  field[n] = '\0';
}

}  // namespace probeless::bus::internal
