#include "topic.h"

#include <unistd.h>

#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <new>
#include <thread>
#include <utility>

#include "probeless/error/error.h"

namespace probeless::bus::internal {
namespace {

constexpr int64_t kMaintenancePeriodNs = 1'000'000'000;
constexpr int64_t kInitTimeoutNs = 1'000'000'000;

std::string Hex(uint64_t v) {
  char buf[24];
  std::snprintf(buf, sizeof(buf), "0x%016" PRIx64, v);
  return buf;
}

bool Alive(const ProcessId& id, bool full_check) {
  return full_check ? DefinitelyAlive(id) : ProbablyAlive(id);
}

}  // namespace

std::shared_ptr<TopicHandle> TopicHandle::Open(const std::string& domain, std::string_view topic,
                                               bool create) {
  ValidateTopicName(topic);
  const std::string name = TopicSegmentName(domain, topic);
  for (int attempt = 0; attempt < 10000; ++attempt) {
    std::shared_ptr<Mapping> mapping;
    if (create) {
      mapping = CreateSegment(name, sizeof(TopicControl));
      if (mapping) {
        // tmpfs hands out zeroed pages: atomics and counters start at 0; mutexes need init.
        auto* ctrl = reinterpret_cast<TopicControl*>(mapping->base());
        ctrl->magic = kTopicMagic;
        ctrl->version = kLayoutVersion;
        InitRobustMutex(&ctrl->mutex);
        for (auto& sub : ctrl->subscribers) InitRobustMutex(&sub.mutex);
        CopyText(ctrl->topic, sizeof(ctrl->topic), topic);
        ctrl->ready.store(1, std::memory_order_release);
      }
    }
    if (!mapping) {
      mapping = OpenSegment(name, sizeof(TopicControl));
      if (!mapping) {
        if (!create) return nullptr;
        std::this_thread::sleep_for(std::chrono::microseconds(50));
        continue;
      }
      auto* ctrl = reinterpret_cast<TopicControl*>(mapping->base());
      const int64_t give_up = MonotonicNowNs() + kInitTimeoutNs;
      while (ctrl->ready.load(std::memory_order_acquire) == 0) {
        if (MonotonicNowNs() > give_up) break;
        std::this_thread::sleep_for(std::chrono::microseconds(50));
      }
      if (ctrl->ready.load(std::memory_order_acquire) == 0) {
        // Its creator died while initialising it: nobody can be registered in it.
        if (!create) return nullptr;
        UnlinkSegment(name);
        continue;
      }
      if (ctrl->magic != kTopicMagic || ctrl->version != kLayoutVersion) {
        throw BusError("topic '" + std::string(topic) + "': segment '" + name +
                       "' has an incompatible layout (another probeless version?); run "
                       "'probeless clean' once no graph is running");
      }
    }
    auto handle = std::shared_ptr<TopicHandle>(new TopicHandle());
    handle->domain_ = domain;
    handle->topic_ = std::string(topic);
    handle->segment_name_ = name;
    handle->mapping_ = std::move(mapping);
    handle->ctrl_ = reinterpret_cast<TopicControl*>(handle->mapping_->base());
    handle->next_maintenance_ns_ = MonotonicNowNs() + kMaintenancePeriodNs;
    return handle;
  }
  throw BusError("topic '" + std::string(topic) + "': cannot open its registry segment '" + name +
                 "' (it keeps disappearing)");
}

void TopicHandle::CheckTypeLocked(const TopicType& type) {
  if (type.name.empty() || type.name.size() > kMaxNameLength) {
    throw BusError("topic '" + topic_ + "': type name must be 1.." +
                   std::to_string(kMaxNameLength) + " characters, got '" + type.name + "'");
  }
  bool anyone = false;
  for (const auto& p : ctrl_->publishers) anyone |= p.state.load() != kFree;
  for (const auto& s : ctrl_->subscribers) anyone |= s.state.load() != kFree;
  if (ctrl_->type_set == 0 || !anyone) {
    CopyText(ctrl_->type_name, sizeof(ctrl_->type_name), type.name);
    ctrl_->layout_hash = type.layout_hash;
    ctrl_->type_set = 1;
    return;
  }
  if (type.name != ctrl_->type_name || type.layout_hash != ctrl_->layout_hash) {
    throw BusError("topic '" + topic_ + "' carries type '" + ctrl_->type_name + "' (layout " +
                   Hex(ctrl_->layout_hash) + "), not '" + type.name + "' (layout " +
                   Hex(type.layout_hash) + ")");
  }
}

PublisherHeader* TopicHandle::Header(const Mapping& mapping) {
  return reinterpret_cast<PublisherHeader*>(mapping.base());
}

SlotHeader* TopicHandle::Slot(const Mapping& mapping, uint32_t slot) {
  PROBELESS_DEMAND(slot < mapping.slot_count, "slot index past the publisher's pool");
  return reinterpret_cast<SlotHeader*>(mapping.base() + SlotsOffset() + slot * mapping.stride);
}

std::string TopicHandle::AdoptPoolGeometry(Mapping& mapping) {
  if (mapping.bytes() < SlotsOffset()) {
    return "its pool segment has " + std::to_string(mapping.bytes()) + " bytes, less than a header";
  }
  const PublisherHeader* h = Header(mapping);
  // One read of each field: the header may change under us.
  const uint64_t magic = *static_cast<const volatile uint64_t*>(&h->magic);
  const uint32_t version = *static_cast<const volatile uint32_t*>(&h->version);
  const uint32_t slot_count = *static_cast<const volatile uint32_t*>(&h->slot_count);
  const uint64_t capacity = *static_cast<const volatile uint64_t*>(&h->capacity);
  const uint64_t stride = *static_cast<const volatile uint64_t*>(&h->stride);
  if (magic != kPublisherMagic || version != kLayoutVersion) {
    return "its pool segment is not a publisher pool of layout version " +
           std::to_string(kLayoutVersion);
  }
  if (slot_count == 0 || slot_count > kMaxSlots || capacity == 0 || capacity > kMaxMessageBytes ||
      stride != AlignUp(kSlotHeaderBytes + capacity, 64) ||
      (mapping.bytes() - SlotsOffset()) / stride < slot_count) {
    return "its pool header says " + std::to_string(slot_count) + " slots of " +
           std::to_string(capacity) + " bytes (stride " + std::to_string(stride) +
           "), which is not a pool of its " + std::to_string(mapping.bytes()) + "-byte segment";
  }
  mapping.slot_count = slot_count;
  mapping.capacity = capacity;
  mapping.stride = stride;
  return "";
}

std::shared_ptr<Mapping> TopicHandle::PublisherMapping(uint32_t index, uint32_t generation,
                                                       std::string* why) {
  if (index >= kMaxPublishersPerTopic) {
    if (why != nullptr) *why = "a queue entry names publisher " + std::to_string(index);
    return nullptr;
  }
  {
    std::lock_guard<std::mutex> guard(cache_mutex_);
    if (cache_[index].mapping && cache_[index].generation == generation) {
      return cache_[index].mapping;
    }
  }
  const PublisherEntry& entry = ctrl_->publishers[index];
  auto current = [&] {
    return entry.state.load(std::memory_order_acquire) != kFree &&
           entry.generation.load(std::memory_order_acquire) == generation;
  };
  if (!current()) return nullptr;
  char segment[kSegmentNameBytes];
  std::memcpy(segment, entry.segment, sizeof(segment));
  segment[kSegmentNameBytes - 1] = '\0';
  const size_t bytes = entry.segment_bytes;
  if (!current()) return nullptr;  // the entry was reused while we read it
  std::shared_ptr<Mapping> mapping = OpenSegment(segment, bytes);
  if (!mapping) return nullptr;
  const std::string invalid = AdoptPoolGeometry(*mapping);
  if (!invalid.empty()) {
    if (why != nullptr) *why = invalid;
    return nullptr;
  }
  std::lock_guard<std::mutex> guard(cache_mutex_);
  cache_[index] = {generation, mapping};
  return mapping;
}

void TopicHandle::DecRef(const QueueEntry& entry) {
  if (IsTombstone(entry)) return;
  auto mapping = PublisherMapping(entry.pub_index, entry.pub_generation);
  if (!mapping) return;  // its publisher is gone (purged or reclaimed): nothing to release
  if (entry.slot >= mapping->slot_count) return;  // a corrupt entry names no slot of the pool
  SlotHeader* slot = Slot(*mapping, entry.slot);
  const uint32_t before = slot->refs.fetch_sub(1, std::memory_order_acq_rel);
  PROBELESS_DEMAND((before & ~kLoanBit) != 0, "slot reference count underflow");
}

bool TopicHandle::Referenced(uint32_t index, uint32_t generation) {
  for (auto& sub : ctrl_->subscribers) {
    if (sub.state.load() != kActive) continue;
    RobustLock lock(&sub.mutex);
    for (uint32_t k = 0; k < sub.count; ++k) {
      const QueueEntry& e = sub.ring[(sub.head + k) % kMaxQueueDepth];
      if (!IsTombstone(e) && e.pub_index == index && e.pub_generation == generation) return true;
    }
    for (uint32_t i = 0; i < kMaxHeldSamples; ++i) {
      const QueueEntry& e = sub.held[i];
      if ((sub.held_mask & (1u << i)) && e.pub_index == index && e.pub_generation == generation) {
        return true;
      }
    }
  }
  return false;
}

void TopicHandle::FreeSubscriberLocked(uint32_t index) {
  SubscriberEntry& sub = ctrl_->subscribers[index];
  {
    RobustLock lock(&sub.mutex);
    std::vector<QueueEntry> refs;
    for (uint32_t i = 0; i < sub.count; ++i)
      refs.push_back(sub.ring[(sub.head + i) % kMaxQueueDepth]);
    for (uint32_t i = 0; i < kMaxHeldSamples; ++i) {
      if (sub.held_mask & (1u << i)) refs.push_back(sub.held[i]);
    }
    sub.count = 0;
    sub.head = 0;
    sub.held_mask = 0;
    OrderStores();  // out of the tables before the references are released
    for (const auto& ref : refs) DecRef(ref);
    sub.state.store(kFree, std::memory_order_release);
    sub.generation += 1;
  }
}

void TopicHandle::RetirePublisherLocked(uint32_t index, bool crashed) {
  PublisherEntry& entry = ctrl_->publishers[index];
  if (entry.state.load() != kActive) return;
  auto mapping = PublisherMapping(index, entry.generation.load());
  if (mapping) {
    PublisherHeader* header = Header(*mapping);
    {
      RobustLock lock(&header->history_mutex);
      for (uint32_t i = 0; i < std::min(header->history_count, kMaxHistory); ++i) {
        const uint32_t slot = header->history_slots[(header->history_head + i) % kMaxHistory];
        if (slot < mapping->slot_count) {
          Slot(*mapping, slot)->refs.fetch_sub(1, std::memory_order_acq_rel);
        }
      }
      header->history_count = 0;
    }
    if (crashed) {
      // Loans its owner never published or returned.
      for (uint32_t s = 0; s < mapping->slot_count; ++s) {
        auto& refs = Slot(*mapping, s)->refs;
        if (refs.load() & kLoanBit) refs.fetch_and(~kLoanBit, std::memory_order_acq_rel);
      }
    }
  }
  entry.state.store(kZombie, std::memory_order_release);
  if (!mapping) {
    // The segment is already gone: nothing can reference it any more.
    entry.state.store(kFree, std::memory_order_release);
    UnlinkSegment(entry.segment);
    return;
  }
  TryFreeZombieLocked(index);
}

bool TopicHandle::TryFreeZombieLocked(uint32_t index) {
  PublisherEntry& entry = ctrl_->publishers[index];
  if (entry.state.load() != kZombie) return false;
  // The subscribers' tables are the truth (a process killed inside a critical section may have
  // left a reference count off by one; a zombie never gains new references).
  if (Referenced(index, entry.generation.load())) return false;
  UnlinkSegment(entry.segment);
  unlinked_.push_back(entry.segment);
  entry.state.store(kFree, std::memory_order_release);
  std::lock_guard<std::mutex> guard(cache_mutex_);
  cache_[index] = {};
  return true;
}

void TopicHandle::PurgeZombieLocked(uint32_t index) {
  PublisherEntry& entry = ctrl_->publishers[index];
  PROBELESS_DEMAND(entry.state.load() == kZombie, "purging a publisher entry that is not a zombie");
  for (auto& sub : ctrl_->subscribers) {
    if (sub.state.load() != kActive) continue;
    RobustLock lock(&sub.mutex);
    // Tombstones, not compaction: a kill mid-shift would leave duplicates (see kTombstoneSlot).
    for (uint32_t k = 0; k < sub.count; ++k) {
      QueueEntry& e = sub.ring[(sub.head + k) % kMaxQueueDepth];
      if (!IsTombstone(e) && e.pub_index == index && e.pub_generation == entry.generation.load()) {
        e.slot = kTombstoneSlot;
        sub.dropped.fetch_add(1, std::memory_order_relaxed);
      }
    }
  }
  UnlinkSegment(entry.segment);
  unlinked_.push_back(entry.segment);
  entry.state.store(kFree, std::memory_order_release);
  std::lock_guard<std::mutex> guard(cache_mutex_);
  cache_[index] = {};
}

void TopicHandle::MaintainLocked(bool full_check) {
  for (uint32_t i = 0; i < kMaxSubscribersPerTopic; ++i) {
    SubscriberEntry& sub = ctrl_->subscribers[i];
    if (sub.state.load() == kActive && !Alive(sub.owner, full_check)) FreeSubscriberLocked(i);
  }
  for (uint32_t i = 0; i < kMaxPublishersPerTopic; ++i) {
    PublisherEntry& pub = ctrl_->publishers[i];
    if (pub.state.load() == kActive && !Alive(pub.owner, full_check)) {
      RetirePublisherLocked(i, /*crashed=*/true);
    }
    if (pub.state.load() == kZombie) TryFreeZombieLocked(i);
  }
  next_maintenance_ns_.store(MonotonicNowNs() + kMaintenancePeriodNs, std::memory_order_relaxed);
}

void TopicHandle::MaintainIfDue() {
  if (MonotonicNowNs() < next_maintenance_ns_.load(std::memory_order_relaxed)) return;
  Maintain();
}

void TopicHandle::Maintain() {
  RobustLock lock(&ctrl_->mutex);
  MaintainLocked(/*full_check=*/false);
}

void TopicHandle::LeaveLocked() {
  ctrl_->registry_version.fetch_add(1, std::memory_order_acq_rel);
  for (const auto& p : ctrl_->publishers) {
    if (p.state.load() != kFree) return;
  }
  for (const auto& s : ctrl_->subscribers) {
    if (s.state.load() != kFree) return;
  }
  ctrl_->dead = 1;
  UnlinkSegment(segment_name_);
  unlinked_.push_back(segment_name_);
}

std::vector<std::string> TopicHandle::TakeUnlinked() { return std::exchange(unlinked_, {}); }

}  // namespace probeless::bus::internal
