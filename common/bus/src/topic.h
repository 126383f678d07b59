// A process's handle on one topic's registry segment (private to common/bus).
#pragma once

#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "shm.h"
#include "shm_layout.h"

namespace probeless::bus::internal {

class TopicHandle {
 public:
  // Maps the topic's registry, creating it if needed. The caller must lock ctrl()->mutex and check
  // ctrl()->dead before registering (see Join).
  static std::shared_ptr<TopicHandle> Open(const std::string& domain, std::string_view topic,
                                           bool create);

  // Opens the topic and runs `register_locked(handle)` under its registry lock, retrying if the
  // registry was being torn down concurrently. Dead participants are reclaimed first.
  template <typename F>
  static std::shared_ptr<TopicHandle> Join(const std::string& domain, std::string_view topic,
                                           F&& register_locked) {
    for (;;) {
      auto handle = Open(domain, topic, /*create=*/true);
      RobustLock lock(&handle->ctrl()->mutex);
      if (handle->ctrl()->dead != 0) continue;
      handle->MaintainLocked(/*full_check=*/true);
      register_locked(*handle);
      handle->ctrl()->registry_version.fetch_add(1, std::memory_order_acq_rel);
      return handle;
    }
  }

  TopicControl* ctrl() const { return ctrl_; }
  const std::string& topic() const { return topic_; }
  const std::string& segment_name() const { return segment_name_; }

  // Throws BusError unless the topic carries `type` (fixes it if no participant did yet). Locked.
  void CheckTypeLocked(const TopicType& type);

  // The mapping of publisher `index` at `generation`, or nullptr if that publisher is gone. Takes
  // no shared-memory lock (the entry is read seqlock-style, validated by its generation), so it may
  // be called under any bus lock.
  // A pool whose header does not describe a valid pool inside the mapping (a faulty or hostile
  // publisher) is not mapped either: nullptr, and `why` (when given) says what was wrong.
  std::shared_ptr<Mapping> PublisherMapping(uint32_t index, uint32_t generation,
                                            std::string* why = nullptr);
  // Validates the pool header of `mapping` (magic, version, slot count, capacity, stride, all
  // slots inside the mapping) and records its geometry in the mapping. Returns "" or the reason.
  static std::string AdoptPoolGeometry(Mapping& mapping);
  // The slot at `slot` (< mapping.slot_count, checked by the callers that read the index from
  // shared memory), by the mapping's validated geometry.
  static SlotHeader* Slot(const Mapping& mapping, uint32_t slot);
  static PublisherHeader* Header(const Mapping& mapping);

  // Drops one reference to the slot a queue entry names. Callers hold the mutex of the subscriber
  // whose queue or held table the entry just left, so reference counts always match those tables
  // whenever all subscriber mutexes are held (see PublisherImpl::AuditSlots).
  void DecRef(const QueueEntry& entry);
  // True if any subscriber's queue or held table names a slot of publisher `index` at `generation`.
  bool Referenced(uint32_t index, uint32_t generation);

  // Reclaims dead participants and frees zombie publishers whose slots are all released. With
  // full_check, liveness also compares process start times (pid reuse). Locked.
  void MaintainLocked(bool full_check);
  // MaintainLocked at most once a second (cheap check otherwise).
  void MaintainIfDue();
  // Takes the lock and maintains now.
  void Maintain();

  // Called by a leaving participant after freeing its entry: unlinks the registry when empty.
  void LeaveLocked();

  // The subscriber entry at `index`, freed and with its references dropped. Locked.
  void FreeSubscriberLocked(uint32_t index);
  // Turns publisher `index` into a zombie after it left or died. Locked.
  void RetirePublisherLocked(uint32_t index, bool crashed);
  // Frees a zombie whose slots are all released; returns true if freed. Locked.
  bool TryFreeZombieLocked(uint32_t index);
  // Frees a zombie even though subscribers still reference it: its queued messages are dropped
  // (counted), samples already taken stay valid (they keep the segment mapped). For when a new
  // publisher needs the registry entry. Locked.
  void PurgeZombieLocked(uint32_t index);

  // Segment names unlinked by maintenance since the last call (for CleanDeadSegments).
  std::vector<std::string> TakeUnlinked();

 private:
  TopicHandle() = default;

  std::string domain_;
  std::string topic_;
  std::string segment_name_;
  std::shared_ptr<Mapping> mapping_;
  TopicControl* ctrl_ = nullptr;
  std::atomic<int64_t> next_maintenance_ns_{0};

  struct CachedMapping {
    uint32_t generation = 0;
    std::shared_ptr<Mapping> mapping;
  };
  std::mutex cache_mutex_;
  CachedMapping cache_[kMaxPublishersPerTopic];
  std::vector<std::string> unlinked_;
};

}  // namespace probeless::bus::internal
