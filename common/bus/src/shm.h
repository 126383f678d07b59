// POSIX shared-memory plumbing of the bus: segment names, mappings, process identity, robust
// mutexes and futexes (private to common/bus).
#pragma once

#include <pthread.h>

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "shm_layout.h"

namespace probeless::bus::internal {

// "probeless.<uid>.<domain>." — every segment of this user and domain starts with it.
std::string SegmentPrefix(const std::string& domain);
// "/a/b_c" -> "a.b_c" (topic names never contain '.').
std::string EncodeTopic(std::string_view topic);
// Inverse of EncodeTopic.
std::string DecodeTopic(std::string_view encoded);
std::string TopicSegmentName(const std::string& domain, std::string_view topic);

// A mapped shared-memory segment; unmaps on destruction (never unlinks).
class Mapping {
 public:
  Mapping(void* base, size_t bytes) : base_(base), bytes_(bytes) {}
  ~Mapping();
  Mapping(const Mapping&) = delete;
  Mapping& operator=(const Mapping&) = delete;
  std::byte* base() const { return static_cast<std::byte*>(base_); }
  size_t bytes() const { return bytes_; }

  // A publisher pool's geometry, validated against the mapped size when the pool was created or
  // mapped (TopicHandle::AdoptPoolGeometry); slots are located with these, never with the pool
  // header's live fields, which a faulty or hostile publisher may overwrite at any time.
  uint32_t slot_count = 0;
  uint64_t capacity = 0;  // payload bytes per slot
  uint64_t stride = 0;    // bytes per slot, SlotHeader included

 private:
  void* base_;
  size_t bytes_;
};

// Creates `name` exclusively (mode 0600) with `bytes` of zeroes and maps it. Returns nullptr if it
// already exists; throws BusError on any other failure.
std::shared_ptr<Mapping> CreateSegment(const std::string& name, size_t bytes);
// Opens and maps an existing segment of at least `min_bytes` (0: whatever size it has). Returns
// nullptr if it does not exist (or is still being sized by its creator); throws BusError otherwise.
std::shared_ptr<Mapping> OpenSegment(const std::string& name, size_t min_bytes);
void UnlinkSegment(const std::string& name);

// This process's identity (computed once).
const ProcessId& Self();
// Reads the start time of `pid`; 0 if the process does not exist or is a zombie.
uint64_t ProcessStartTime(int32_t pid);
// Cheap check (one kill(pid, 0)): false only if the process certainly no longer exists.
bool ProbablyAlive(const ProcessId& id);
// Full check: exists, is not a zombie, and has the recorded start time.
bool DefinitelyAlive(const ProcessId& id);

void InitRobustMutex(pthread_mutex_t* mutex);

// Locks a robust process-shared mutex; recovers it if its previous owner died.
class RobustLock {
 public:
  explicit RobustLock(pthread_mutex_t* mutex);
  ~RobustLock();
  RobustLock(const RobustLock&) = delete;
  RobustLock& operator=(const RobustLock&) = delete;
  // True if the previous owner died holding the lock (state it guarded may be mid-update).
  bool recovered() const { return recovered_; }

 private:
  pthread_mutex_t* mutex_;
  bool recovered_ = false;
};

// Shared (not process-private) futex operations on a 32-bit word in shared memory.
void FutexWakeAll(std::atomic<uint32_t>* word);
// Waits while *word == expected, at most until `deadline` (CLOCK_MONOTONIC ns). Returns on wake,
// value change, timeout or signal.
void FutexWait(std::atomic<uint32_t>* word, uint32_t expected, int64_t deadline_mono_ns);
// Waits on several words at once (futex_waitv, Linux >= 5.16); returns like FutexWait.
void FutexWaitMany(std::atomic<uint32_t>* const* words, const uint32_t* expected, size_t count,
                   int64_t deadline_mono_ns);

int64_t MonotonicNowNs();
int64_t WallNowNs();

// Copies `text` into a fixed NUL-terminated field.
void CopyText(char* field, size_t field_bytes, std::string_view text);

}  // namespace probeless::bus::internal
