// The binary layout of the bus's shared-memory segments (private to common/bus).
//
// Topic segment "probeless.<uid>.<domain>.t.<topic>": one TopicControl, the registry of a topic.
// Publisher segment "probeless.<uid>.<domain>.p.<pid>.<n>.<topic>": a PublisherHeader, then
// slot_count slots of `stride` bytes, each a SlotHeader followed by the payload.
//
// Lock order (never take a lock earlier in this list while holding a later one):
//   TopicControl::mutex  <  PublisherHeader::history_mutex  <  SubscriberEntry::mutex
// All mutexes are process-shared and robust: a holder killed with -9 hands the next locker
// EOWNERDEAD, which marks the mutex consistent again (see LockRobust).
//
// Slot reference counts: bit 31 is the owner's loan (set by Borrow, cleared by Publish or by the
// loan's destruction, or by the reclaimer of a crashed publisher); the low bits count queue
// entries, held samples and history entries that point at the slot. A slot is free when the count
// is 0.
#pragma once

#include <pthread.h>

#include <atomic>
#include <cstddef>
#include <cstdint>

#include "probeless/bus/bus.h"

namespace probeless::bus::internal {

inline constexpr uint64_t kTopicMagic = 0x31706f746c627270ull;      // "prbltop1"
inline constexpr uint64_t kPublisherMagic = 0x3162757062726270ull;  // "prbpub1"
inline constexpr uint32_t kLayoutVersion = 1;
inline constexpr uint32_t kLoanBit = 1u << 31;
inline constexpr size_t kSlotHeaderBytes = 64;
inline constexpr size_t kSegmentNameBytes = 192;
inline constexpr size_t kTextBytes = kMaxNameLength + 4;
inline constexpr uint32_t kMaxSlots = 1024;                  // slots per publisher pool
inline constexpr size_t kMaxMessageBytes = size_t{1} << 30;  // payload bytes per slot

// Identity of a process: pid plus its start time (clock ticks since boot, /proc/<pid>/stat field
// 22), so a recycled pid is not mistaken for the original process.
struct ProcessId {
  int32_t pid = 0;
  uint32_t reserved = 0;
  uint64_t start_time = 0;
};

enum EntryState : uint32_t {
  kFree = 0,
  kActive = 1,
  // A publisher that left (or died) while subscribers still reference its slots. Its segment stays
  // until every reference is released, so nothing already published is lost.
  kZombie = 2,
};

// A queued or held reference to a slot of a publisher of the same topic.
struct QueueEntry {
  uint32_t pub_index;
  uint32_t pub_generation;
  uint32_t slot;
  uint32_t reserved;
};

// A queue entry removed from the middle of a ring (stolen by drop-oldest at the pool, or purged
// with a zombie publisher) is overwritten with this slot value instead of shifting the ring: a
// shift would leave a transient duplicate that a process killed mid-shift turns into a double
// release. Tombstones hold no reference; whoever pops one discards it.
inline constexpr uint32_t kTombstoneSlot = 0xFFFFFFFFu;
inline bool IsTombstone(const QueueEntry& e) { return e.slot == kTombstoneSlot; }

// Crash-safety rule for every table that holds slot references (rings, held samples, history):
// a process may be killed between any two stores, so each mutation is ordered such that a
// reference is never named by more tables than its count says. Add to the count before inserting;
// remove from the table (and fence) before releasing the count. A kill then leaks at most one
// reference, which the owner's audit (Publisher::Borrow when the pool is exhausted) repairs, and
// never frees a slot that a queue still names.
inline void OrderStores() {
#if defined(__SANITIZE_THREAD__)
  // TSan models no fences; these stores are all made under a mutex, which it does model.
  std::atomic_signal_fence(std::memory_order_seq_cst);
#else
  std::atomic_thread_fence(std::memory_order_release);
#endif
}

struct alignas(64) SubscriberEntry {
  std::atomic<uint32_t> state;  // EntryState; changes only under topic mutex and this mutex
  uint32_t generation;          // +1 every time the entry is freed
  ProcessId owner;
  char node_name[kTextBytes];
  pthread_mutex_t mutex;  // guards everything below but the atomics
  uint32_t depth;
  uint32_t head;       // ring index of the oldest entry
  uint32_t count;      // entries in the ring
  uint32_t held_mask;  // bit i: held[i] in use
  QueueEntry ring[kMaxQueueDepth];
  QueueEntry held[kMaxHeldSamples];
  alignas(64) std::atomic<uint32_t> futex;  // +1 after every push; subscribers wait on it
  std::atomic<uint32_t> waiters;            // subscribers blocked (or about to block) on futex
  std::atomic<uint64_t> received;
  std::atomic<uint64_t> dropped;
};

// Pops tombstones at the head of `sub`'s ring (caller holds sub.mutex): they hold no reference.
inline void PopLeadingTombstones(SubscriberEntry& sub) {
  while (sub.count > 0 && IsTombstone(sub.ring[sub.head])) {
    sub.head = (sub.head + 1) % kMaxQueueDepth;
    sub.count -= 1;
  }
}

// Messages really queued in `sub`'s ring, tombstones excluded (caller holds sub.mutex).
inline uint32_t LiveCount(const SubscriberEntry& sub) {
  uint32_t n = 0;
  for (uint32_t k = 0; k < sub.count; ++k)
    n += !IsTombstone(sub.ring[(sub.head + k) % kMaxQueueDepth]);
  return n;
}

struct alignas(64) PublisherEntry {
  std::atomic<uint32_t> state;       // EntryState; changes only under the topic mutex
  std::atomic<uint32_t> generation;  // +1 every time the entry is taken (before its fields change)
  ProcessId owner;
  char segment[kSegmentNameBytes];
  char node_name[kTextBytes];
  uint64_t capacity;  // payload bytes per slot
  uint64_t stride;    // bytes per slot including its SlotHeader
  uint64_t segment_bytes;
  uint32_t slot_count;
  uint32_t history;
  std::atomic<uint64_t> published;
  std::atomic<uint64_t> published_bytes;
  std::atomic<int64_t> last_publish_mono_ns;
};

struct TopicControl {
  uint64_t magic;
  uint32_t version;
  std::atomic<uint32_t> ready;  // 1 once the creator finished initialising
  pthread_mutex_t mutex;        // the registry lock
  uint32_t dead;                // 1: emptied and unlinked; joiners must retry with a new segment
  uint32_t type_set;            // 1 once type_name/layout_hash are fixed by the first participant
  char topic[kTextBytes];
  char type_name[kTextBytes];
  uint64_t layout_hash;
  std::atomic<uint32_t> registry_version;  // +1 on every join/leave; subscribers re-map on change
  PublisherEntry publishers[kMaxPublishersPerTopic];
  SubscriberEntry subscribers[kMaxSubscribersPerTopic];
};

struct alignas(64) SlotHeader {
  std::atomic<uint32_t> refs;
  uint32_t size;
  uint64_t sequence;
  int64_t publish_mono_ns;
  int64_t publish_wall_ns;
};
static_assert(sizeof(SlotHeader) == kSlotHeaderBytes);

struct alignas(64) PublisherHeader {
  uint64_t magic;
  uint32_t version;
  uint32_t slot_count;
  uint64_t capacity;
  uint64_t stride;
  ProcessId owner;
  pthread_mutex_t history_mutex;  // guards the history ring; held across a publish's fan-out
  uint32_t history;               // K
  uint32_t history_head;          // oldest
  uint32_t history_count;
  uint32_t history_slots[kMaxHistory];
};

inline size_t AlignUp(size_t v, size_t a) { return (v + a - 1) / a * a; }

inline size_t SlotsOffset() { return (sizeof(PublisherHeader) + 4095) / 4096 * 4096; }

}  // namespace probeless::bus::internal
