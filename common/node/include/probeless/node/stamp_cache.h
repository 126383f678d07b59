// probeless node runtime: the recent messages of one topic keyed by header stamp, for pairing
// topics by stamp (ROS message_filters' Cache with its exact and latest-before lookups).
//
// Model
// - A StampCache<T> holds at most capacity() values, each with the header.stamp_ns (nanoseconds,
//   the message's own clock) it was added under, oldest first. T is what a node keeps of a message:
//   a struct copy (msgs::Pose), something decoded from it, or a HeldMessage (below) of a message
//   with a payload.
// - Stamps are expected not to decrease. A stamp below the newest held one is a restarted source (a
//   replay from its beginning, a camera restarted): Add clears the cache before inserting, so
//   nothing of the old stream matches the new one. Held stamps therefore never decrease, oldest
//   to newest. An equal stamp (a duplicate) is kept after the ones already held.
// - A full cache evicts its oldest value when one is added.
// - Lookups return a pointer into the cache (nullptr: no match), valid until the next Add,
//   DropUpTo or Clear.
//
//   node::StampCache<msgs::Pose> poses(8);                    // scene_light's camera poses
//   poses.Add(pose.header.stamp_ns, pose);                    // on each scene/pose
//   if (const msgs::Pose* p = poses.LatestAtOrBefore(stamp))  // on each frame
//
// Thread safety: none; one thread at a time (normally the node's Spin thread).
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <limits>
#include <optional>
#include <span>
#include <utility>
#include <vector>

namespace probeless::node {

// The tolerance of a LatestAtOrBefore without an age limit.
inline constexpr int64_t kAnyAge = std::numeric_limits<int64_t>::max();

namespace stamp_cache_detail {
// Throws NodeError "StampCache: capacity must be >= 1".
[[noreturn]] void ThrowZeroCapacity();
// Whether `stamp_ns` <= `at_ns` and at_ns - stamp_ns <= tolerance_ns (no overflow for any
// stamps; kAnyAge: any age; a negative tolerance: false).
bool WithinTolerance(int64_t stamp_ns, int64_t at_ns, int64_t tolerance_ns);
}  // namespace stamp_cache_detail

template <class T>
class StampCache {
 public:
  // A cache of at most `capacity` values. Throws NodeError for capacity 0.
  explicit StampCache(size_t capacity) : capacity_(capacity) {
    if (capacity == 0) stamp_cache_detail::ThrowZeroCapacity();
  }

  // Adds `value` as the newest, under `stamp_ns`. A stamp below newest_stamp() clears the cache
  // first (a restarted source; counted by resets()) and returns true; otherwise returns false. A
  // full cache drops its oldest value. An equal stamp is a duplicate, kept after the others.
  bool Add(int64_t stamp_ns, T value) {
    const bool reset = !entries_.empty() && stamp_ns < entries_.back().stamp_ns;
    if (reset) {
      entries_.clear();
      ++resets_;
    }
    if (entries_.size() == capacity_) entries_.pop_front();
    entries_.push_back({stamp_ns, std::move(value)});
    return reset;
  }

  // The value with stamp exactly `stamp_ns` (among duplicates the oldest, the first added), or
  // nullptr.
  const T* Exact(int64_t stamp_ns) const {
    for (const Entry& e : entries_) {
      if (e.stamp_ns == stamp_ns) return &e.value;
      if (e.stamp_ns > stamp_ns) break;
    }
    return nullptr;
  }
  // The same, for changing the held value in place.
  T* Exact(int64_t stamp_ns) { return const_cast<T*>(std::as_const(*this).Exact(stamp_ns)); }

  // The newest value with a stamp at or before `stamp_ns` and at most `tolerance_ns` older than
  // it, i.e. in [stamp_ns - tolerance_ns, stamp_ns] (among duplicates the newest, the last added),
  // or nullptr. kAnyAge: no age limit; a negative tolerance matches nothing.
  const T* LatestAtOrBefore(int64_t stamp_ns, int64_t tolerance_ns = kAnyAge) const {
    for (auto it = entries_.rbegin(); it != entries_.rend(); ++it) {
      if (it->stamp_ns > stamp_ns) continue;
      return stamp_cache_detail::WithinTolerance(it->stamp_ns, stamp_ns, tolerance_ns) ? &it->value
                                                                                       : nullptr;
    }
    return nullptr;
  }

  // Removes every value with a stamp <= `stamp_ns` (they can match no later lookup of a source
  // whose stamps do not decrease); returns how many.
  size_t DropUpTo(int64_t stamp_ns) {
    size_t dropped = 0;
    while (!entries_.empty() && entries_.front().stamp_ns <= stamp_ns) {
      entries_.pop_front();
      ++dropped;
    }
    return dropped;
  }

  // Removes every value (not counted by resets()).
  void Clear() { entries_.clear(); }

  // Values held (duplicates included), at most capacity().
  size_t size() const { return entries_.size(); }
  bool empty() const { return entries_.empty(); }
  // The bound given to the constructor.
  size_t capacity() const { return capacity_; }
  // The newest value's stamp, or nullopt when empty.
  std::optional<int64_t> newest_stamp() const {
    if (entries_.empty()) return std::nullopt;
    return entries_.back().stamp_ns;
  }
  // How often Add cleared the cache for a stamp going backwards.
  uint64_t resets() const { return resets_; }

 private:
  struct Entry {
    int64_t stamp_ns;
    T value;
  };
  size_t capacity_;
  std::deque<Entry> entries_;  // stamps non-decreasing, oldest first
  uint64_t resets_ = 0;
};

// A copy of a bus sample's bytes (header and payload), aligned to msgs::kPayloadAlignment as
// msgs::ReadMessage needs: for keeping more messages than a subscriber may hold as samples
// (bus::kMaxHeldSamples). Move-only (a copy would lose the alignment).
class HeldMessage {
 public:
  HeldMessage() = default;
  // Copies `bytes`.
  explicit HeldMessage(std::span<const std::byte> bytes);
  // A moved-from HeldMessage is empty.
  HeldMessage(HeldMessage&& other) noexcept
      : storage_(std::move(other.storage_)),
        offset_(std::exchange(other.offset_, 0)),
        size_(std::exchange(other.size_, 0)) {}
  HeldMessage& operator=(HeldMessage&& other) noexcept {
    if (this == &other) return *this;
    storage_ = std::move(other.storage_);
    offset_ = std::exchange(other.offset_, 0);
    size_ = std::exchange(other.size_, 0);
    return *this;
  }
  HeldMessage(const HeldMessage&) = delete;
  HeldMessage& operator=(const HeldMessage&) = delete;

  // The copied bytes, starting at a multiple of msgs::kPayloadAlignment (empty for a
  // default-constructed one).
  std::span<const std::byte> bytes() const { return {storage_.data() + offset_, size_}; }

 private:
  std::vector<std::byte> storage_;
  size_t offset_ = 0, size_ = 0;
};

}  // namespace probeless::node
