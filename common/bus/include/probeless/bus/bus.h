// probeless bus: a daemonless, zero-copy publish/subscribe bus over POSIX shared memory.
//
// Model
// - A topic is a name such as "/camera/image". All participants of a topic share one small control
//   segment (the registry: type, publishers, subscribers and their queues). Each publisher owns one
//   data segment holding a pool of fixed-capacity slots; a message lives in a slot and is never
//   copied: the publisher loans a slot, fills it in place and publishes it; every subscriber gets a
//   read-only view of the same bytes, valid until it releases the sample (reference counts in
//   shared memory).
// - Every subscriber has its own bounded queue (depth, default 2). A full queue drops its oldest
//   entry: a slow subscriber never blocks the publisher, and its drops are counted.
// - Optional per-publisher history of the last K messages, handed to subscribers that join later.
// - Subscribers block on a futex in shared memory (no polling loop) or poll with TryTake; a WaitSet
//   blocks on several subscribers at once (futex_waitv).
// - Crash robustness: participants are identified by (pid, process start time). A participant that
//   died (kill -9) is detected by whoever touches the topic next; its slots and queue entries are
//   reclaimed and its segment unlinked. Restarting under the same names needs no manual cleanup.
// - Segments are created mode 0600 and named "probeless.<uid>.<domain>.…" in /dev/shm, so users and
//   domains (PROBELESS_DOMAIN) never see each other's topics.
//
// Thread safety: a Publisher or Subscriber object is used by one thread at a time. Different
// objects (also on the same topic, in one process or many) are independent.
//
// Errors: bad input at the boundary (invalid topic name, type mismatch, message larger than the
// topic's capacity, exhausted limits) throws BusError with a one-line message naming the topic and
// what was expected. Broken invariants of the shared state abort through assertions.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/error/error.h"

namespace probeless::bus {

// The single exception type of the bus; what() is one line naming the topic and the problem.
class BusError : public InputError {
 public:
  using InputError::InputError;
};

// Hard limits of one topic (compile-time, part of the shared layout).
inline constexpr uint32_t kMaxPublishersPerTopic = 8;
inline constexpr uint32_t kMaxSubscribersPerTopic = 32;
inline constexpr uint32_t kMaxQueueDepth = 64;   // a subscriber's queue depth is 1..64
inline constexpr uint32_t kMaxHeldSamples = 16;  // samples one subscriber may hold at once
inline constexpr uint32_t kMaxHistory = 16;      // late-joiner history per publisher
inline constexpr size_t kMaxNameLength = 100;    // topic names, type names, node names

// The type a topic carries: a type name ("probeless_msgs/Image") and a hash of its binary layout.
// Publishers and subscribers of one topic must agree on both.
struct TopicType {
  std::string name;
  uint64_t layout_hash = 0;
};

// Per-message metadata written by the bus at Publish().
struct MessageInfo {
  uint64_t sequence = 0;        // 1, 2, 3, … per publisher
  int64_t publish_mono_ns = 0;  // CLOCK_MONOTONIC at Publish(), nanoseconds
  int64_t publish_wall_ns = 0;  // CLOCK_REALTIME at Publish(), nanoseconds since the Unix epoch
  uint32_t size = 0;            // payload bytes
  int32_t publisher_pid = 0;
  uint32_t publisher_index = 0;  // registry index of the publisher within its topic
};

struct PublisherOptions {
  // Largest payload in bytes a message of this publisher may have (capacity of every slot).
  size_t max_message_bytes = 0;
  // Slots in the pool. Untouched slots cost no memory (tmpfs pages are allocated on first write and
  // the lowest free slot is always reused first). Loan() throws when every slot is referenced.
  uint32_t slot_count = 32;
  // Last K published messages kept for subscribers that join later (0..kMaxHistory).
  uint32_t history = 0;
  // Shown by introspection ("probeless topic info").
  std::string node_name;
};

struct SubscriberOptions {
  // Queue depth 1..kMaxQueueDepth; a full queue drops its oldest entry.
  uint32_t queue_depth = 2;
  // Receive the publishers' history (if they keep one) when joining.
  bool receive_history = true;
  std::string node_name;
};

namespace internal {
class TopicHandle;
struct PublisherImpl;
struct SubscriberImpl;
struct SampleRef;
}  // namespace internal

// A slot loaned from a publisher's pool: fill data() in place, then Publisher::Publish(). A loan
// dropped without publishing returns its slot to the pool. Move-only.
class Loan {
 public:
  Loan() = default;
  Loan(Loan&& other) noexcept;
  Loan& operator=(Loan&& other) noexcept;
  ~Loan();
  Loan(const Loan&) = delete;
  Loan& operator=(const Loan&) = delete;

  // Writable payload of size() bytes (64-byte aligned).
  std::span<std::byte> data() const { return {data_, size_}; }
  size_t size() const { return size_; }
  // Shrinks or grows the payload within the slot capacity (throws BusError beyond it).
  void Resize(size_t bytes);
  size_t capacity() const { return capacity_; }
  bool valid() const { return data_ != nullptr; }

  template <typename T>
  T* As() const {
    return reinterpret_cast<T*>(data_);
  }

 private:
  friend class Publisher;
  std::shared_ptr<internal::PublisherImpl> owner_;
  uint32_t slot_ = 0;
  std::byte* data_ = nullptr;
  size_t size_ = 0;
  size_t capacity_ = 0;
};

// A received message: a read-only view into the publisher's slot, valid until destroyed (the slot
// is released then). Move-only. May outlive the Subscriber that took it.
class Sample {
 public:
  Sample() = default;
  Sample(Sample&& other) noexcept;
  Sample& operator=(Sample&& other) noexcept;
  ~Sample();
  Sample(const Sample&) = delete;
  Sample& operator=(const Sample&) = delete;

  std::span<const std::byte> data() const { return {data_, info_.size}; }
  const MessageInfo& info() const { return info_; }
  bool valid() const { return data_ != nullptr; }
  // Releases the slot now (idempotent).
  void Release();

  template <typename T>
  const T* As() const {
    return reinterpret_cast<const T*>(data_);
  }

 private:
  friend class Subscriber;
  std::shared_ptr<internal::SubscriberImpl> owner_;
  std::shared_ptr<void> mapping_;  // keeps the publisher's segment mapped
  uint32_t held_index_ = 0;
  const std::byte* data_ = nullptr;
  MessageInfo info_;
};

class Publisher {
 public:
  // Joins (or creates) `topic` as a publisher of `type`. Throws BusError on an invalid name, a type
  // mismatch with the topic, options out of range, or a topic with kMaxPublishersPerTopic already.
  Publisher(std::string_view topic, const TopicType& type, const PublisherOptions& options);
  ~Publisher();
  Publisher(Publisher&&) noexcept;
  Publisher& operator=(Publisher&&) noexcept;

  // Loans a free slot with `bytes` of payload (≤ max_message_bytes). When every slot is referenced,
  // the oldest queued (not yet taken) message of this publisher is dropped from the slowest
  // subscriber's queue until one is free, so deep queues never block the publisher. Throws BusError
  // if the message is too large or every slot is held by taken samples or unpublished loans.
  Loan Borrow(size_t bytes);
  // Publishes a loan of this publisher to every current subscriber; the loan becomes invalid.
  // Returns the message's sequence number.
  uint64_t Publish(Loan&& loan);
  // Convenience: Borrow + copy + Publish.
  uint64_t PublishCopy(std::span<const std::byte> bytes);

  // Number of live subscribers registered on the topic (dead ones not yet reclaimed excluded).
  uint32_t SubscriberCount() const;
  const std::string& topic() const;
  size_t max_message_bytes() const;

 private:
  std::shared_ptr<internal::PublisherImpl> impl_;
};

class Subscriber {
 public:
  // Joins (or creates) `topic` as a subscriber of `type`. Throws BusError on an invalid name, a
  // type mismatch with the topic, options out of range, or kMaxSubscribersPerTopic reached.
  Subscriber(std::string_view topic, const TopicType& type, const SubscriberOptions& options = {});
  ~Subscriber();
  Subscriber(Subscriber&&) noexcept;
  Subscriber& operator=(Subscriber&&) noexcept;

  // The oldest queued message, if any; never blocks. Throws BusError if kMaxHeldSamples samples of
  // this subscriber are still held.
  std::optional<Sample> TryTake();
  // Blocks until a message is queued or `timeout` passes (nullopt then).
  std::optional<Sample> Take(std::chrono::nanoseconds timeout);

  // Messages this subscriber lost to drop-oldest so far (and those rejected, below, and those
  // counted by CountDownstreamDrops).
  uint64_t dropped() const;
  // Counts `n` messages this subscriber took but a downstream stage of the same process dropped
  // (e.g. a bridge's per-client queue dropping its oldest entry): they are added to the
  // subscriber's shared drop counter, so dropped() and introspection (`probeless topic info`,
  // SubscriberSnapshot::dropped) include them. Thread-safe (an atomic add in shared memory): may be
  // called from any thread, also while another one uses this subscriber.
  void CountDownstreamDrops(uint64_t n);
  // Messages this subscriber object dropped because their publisher broke the pool's contract (a
  // faulty or hostile process writing the shared memory): a slot size beyond the slot capacity, a
  // pool header that does not describe a pool inside its segment, a queue entry naming no slot.
  // Such a message is never handed out (a Sample's bytes always lie inside its slot); it counts in
  // dropped() too. last_rejection() is the latest one's line, "topic '/t': message of publisher
  // pid N dropped: <what was wrong>" ("of an unknown publisher" for an entry naming none; "" if
  // none was rejected).
  uint64_t rejected() const;
  const std::string& last_rejection() const;
  // Messages currently queued for this subscriber.
  uint32_t queued() const;
  // Number of live publishers registered on the topic (dead ones not yet reclaimed excluded).
  uint32_t PublisherCount() const;
  const std::string& topic() const;

 private:
  friend class WaitSet;
  std::shared_ptr<internal::SubscriberImpl> impl_;
};

// Blocks on several subscribers at once. The subscribers must outlive the WaitSet.
class WaitSet {
 public:
  // Returns the index of the first subscriber (in Add order) found ready.
  size_t Add(Subscriber& subscriber);
  // Indices of the subscribers that have queued messages; empty after `timeout`.
  std::vector<size_t> Wait(std::chrono::nanoseconds timeout);

 private:
  std::vector<Subscriber*> subscribers_;
};

// The domain of this process: $PROBELESS_DOMAIN, or "0". Letters, digits and '_' only.
std::string CurrentDomain();

// Throws BusError unless `topic` is a valid absolute topic name: "/" followed by segments of
// [A-Za-z0-9_] separated by single "/", at most kMaxNameLength characters.
void ValidateTopicName(std::string_view topic);

// --- Introspection (used by "probeless topic" and "probeless clean"). ---

struct PublisherSnapshot {
  int32_t pid = 0;
  bool alive = false;
  std::string node_name;
  size_t max_message_bytes = 0;
  uint32_t slot_count = 0;
  uint32_t history = 0;
  uint64_t published = 0;            // messages since the publisher joined
  uint64_t published_bytes = 0;      // payload bytes since the publisher joined
  int64_t last_publish_mono_ns = 0;  // CLOCK_MONOTONIC ns of the last Publish()
};

struct SubscriberSnapshot {
  int32_t pid = 0;
  bool alive = false;
  std::string node_name;
  uint32_t queue_depth = 0;
  uint32_t queued = 0;
  uint64_t received = 0;
  uint64_t dropped = 0;
};

struct TopicSnapshot {
  std::string topic;
  TopicType type;
  std::vector<PublisherSnapshot> publishers;
  std::vector<SubscriberSnapshot> subscribers;
};

// All topics of this user in `domain`, read without joining them (no effect on the topics).
std::vector<TopicSnapshot> ListTopics(const std::string& domain = CurrentDomain());

// Removes this user's segments in `domain` that belong only to dead processes (and reclaims dead
// participants of live topics). Never touches a segment of a live participant. Returns the names
// of the segments removed from /dev/shm.
std::vector<std::string> CleanDeadSegments(const std::string& domain = CurrentDomain());

}  // namespace probeless::bus
