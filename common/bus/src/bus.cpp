#include "probeless/bus/bus.h"

#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <utility>

#include "probeless/error/error.h"
#include "shm.h"
#include "topic.h"

namespace probeless::bus {
namespace internal {
namespace {

std::atomic<uint32_t> g_publisher_counter{0};

}  // namespace

struct PublisherImpl {
  std::shared_ptr<TopicHandle> topic;
  uint32_t index = 0;
  uint32_t generation = 0;
  std::string segment_name;
  std::shared_ptr<Mapping> mapping;
  PublisherHeader* header = nullptr;
  PublisherEntry* entry = nullptr;
  size_t capacity = 0;
  uint32_t history = 0;
  uint64_t sequence = 0;

  SlotHeader* Slot(uint32_t slot) const { return TopicHandle::Slot(*mapping, slot); }

  // Drop-oldest at the pool: removes the oldest entry naming one of our slots from the queue of the
  // subscriber that has most of them queued (the slowest), counting it as that subscriber's drop.
  // Returns false if no queue holds any of our slots (then only held samples pin them).
  bool StealOldestQueued() {
    TopicControl* ctrl = topic->ctrl();
    auto mine = [&](const QueueEntry& e) {
      return !IsTombstone(e) && e.pub_index == index && e.pub_generation == generation;
    };
    int best = -1;
    uint32_t best_count = 0;
    for (uint32_t i = 0; i < kMaxSubscribersPerTopic; ++i) {
      SubscriberEntry& sub = ctrl->subscribers[i];
      if (sub.state.load(std::memory_order_acquire) != kActive) continue;
      RobustLock lock(&sub.mutex);
      uint32_t n = 0;
      for (uint32_t k = 0; k < sub.count; ++k) n += mine(sub.ring[(sub.head + k) % kMaxQueueDepth]);
      if (n > best_count) {
        best = static_cast<int>(i);
        best_count = n;
      }
    }
    if (best < 0) return false;
    SubscriberEntry& sub = ctrl->subscribers[best];
    std::optional<QueueEntry> stolen;
    {
      RobustLock lock(&sub.mutex);
      internal::PopLeadingTombstones(sub);
      for (uint32_t k = 0; k < sub.count; ++k) {
        if (!mine(sub.ring[(sub.head + k) % kMaxQueueDepth])) continue;
        QueueEntry& victim = sub.ring[(sub.head + k) % kMaxQueueDepth];
        stolen = victim;
        if (k == 0) {  // the oldest of all: pop it
          sub.head = (sub.head + 1) % kMaxQueueDepth;
          sub.count -= 1;
        } else {
          victim.slot = kTombstoneSlot;  // no shift: see kTombstoneSlot
        }
        OrderStores();
        sub.dropped.fetch_add(1, std::memory_order_relaxed);
        Slot(stolen->slot)->refs.fetch_sub(1, std::memory_order_acq_rel);
        break;
      }
    }
    return true;  // stolen, or consumed meanwhile: try the pool again
  }

  // Recomputes the reference counts of our slots from the tables that hold the references (every
  // subscriber's queue and held samples, and our history), under all their locks. Repairs counts
  // left off by a participant killed inside a critical section. Returns the slots repaired.
  uint32_t AuditSlots() {
    TopicControl* ctrl = topic->ctrl();
    RobustLock topic_lock(&ctrl->mutex);
    RobustLock history_lock(&header->history_mutex);
    std::vector<std::unique_ptr<RobustLock>> sub_locks;
    std::vector<uint32_t> counts(mapping->slot_count, 0);
    auto count = [&](const QueueEntry& e) {
      if (e.pub_index == index && e.pub_generation == generation && e.slot < counts.size()) {
        counts[e.slot] += 1;
      }
    };
    for (auto& sub : ctrl->subscribers) {
      sub_locks.push_back(std::make_unique<RobustLock>(&sub.mutex));
      if (sub.state.load() != kActive) continue;
      for (uint32_t k = 0; k < sub.count; ++k) count(sub.ring[(sub.head + k) % kMaxQueueDepth]);
      for (uint32_t i = 0; i < kMaxHeldSamples; ++i) {
        if (sub.held_mask & (1u << i)) count(sub.held[i]);
      }
    }
    for (uint32_t i = 0; i < header->history_count; ++i) {
      counts[header->history_slots[(header->history_head + i) % kMaxHistory]] += 1;
    }
    uint32_t repaired = 0;
    for (uint32_t s = 0; s < mapping->slot_count; ++s) {
      auto& refs = Slot(s)->refs;
      const uint32_t before = refs.load();
      const uint32_t after = (before & kLoanBit) | counts[s];
      if (before != after) {
        refs.store(after, std::memory_order_release);
        ++repaired;
      }
    }
    return repaired;
  }
  std::byte* Payload(uint32_t slot) const {
    return reinterpret_cast<std::byte*>(Slot(slot)) + kSlotHeaderBytes;
  }

  ~PublisherImpl() {
    if (!topic) return;
    try {
      RobustLock lock(&topic->ctrl()->mutex);
      topic->RetirePublisherLocked(index, /*crashed=*/false);
      topic->LeaveLocked();
    } catch (const BusError&) {
      // Destructors must not throw; the next participant's maintenance reclaims the entry.
    }
  }
};

struct SubscriberImpl {
  std::shared_ptr<TopicHandle> topic;
  uint32_t index = 0;
  SubscriberEntry* entry = nullptr;
  uint64_t rejected = 0;
  std::string last_rejection;

  // Records a message dropped because its publisher's slot, pool or queue entry is invalid.
  void Reject(uint32_t pub_index, const std::string& why) {
    ++rejected;
    const std::string from =
        pub_index < kMaxPublishersPerTopic
            ? "publisher pid " + std::to_string(topic->ctrl()->publishers[pub_index].owner.pid)
            : std::string("an unknown publisher");
    last_rejection = "topic '" + topic->topic() + "': message of " + from + " dropped: " + why;
  }

  // Releases held[held_index] (a Sample's slot).
  void Release(uint32_t held_index) {
    QueueEntry ref{};
    {
      RobustLock lock(&entry->mutex);
      PROBELESS_DEMAND(entry->held_mask & (1u << held_index),
                       "releasing a slot the subscriber does not hold");
      ref = entry->held[held_index];
      entry->held_mask &= ~(1u << held_index);
      OrderStores();
      topic->DecRef(ref);
    }
    if (topic->ctrl()->publishers[ref.pub_index].state.load(std::memory_order_acquire) == kZombie) {
      topic->Maintain();
    }
  }

  ~SubscriberImpl() {
    if (!topic) return;
    try {
      RobustLock lock(&topic->ctrl()->mutex);
      topic->FreeSubscriberLocked(index);
      topic->MaintainLocked(/*full_check=*/false);
      topic->LeaveLocked();
    } catch (const BusError&) {
      // Destructors must not throw; the next participant's maintenance reclaims the entry.
    }
  }
};

}  // namespace internal

using internal::IsTombstone;
using internal::kActive;
using internal::kFree;
using internal::kLoanBit;
using internal::OrderStores;
using internal::QueueEntry;
using internal::RobustLock;
using internal::TopicHandle;

// ----------------------------------------------------------------------------------------------
// Names and domains.

std::string CurrentDomain() {
  const char* env = std::getenv("PROBELESS_DOMAIN");
  std::string domain = (env != nullptr && *env != '\0') ? env : "0";
  if (domain.size() > 32) {
    throw BusError("PROBELESS_DOMAIN '" + domain + "' is longer than 32 characters");
  }
  for (char c : domain) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_')) {
      throw BusError("PROBELESS_DOMAIN '" + domain +
                     "' may contain only letters, digits and '_' (expected e.g. 0 or lab_2)");
    }
  }
  return domain;
}

void ValidateTopicName(std::string_view topic) {
  auto fail = [&](const std::string& why) {
    throw BusError("invalid topic name '" + std::string(topic) + "': " + why);
  };
  if (topic.empty() || topic[0] != '/') fail("must start with '/' (expected e.g. /camera/image)");
  if (topic.size() == 1) fail("must name something after '/'");
  if (topic.size() > kMaxNameLength) {
    fail("longer than " + std::to_string(kMaxNameLength) + " characters");
  }
  if (topic.back() == '/') fail("must not end with '/'");
  char previous = '\0';
  for (char c : topic) {
    if (c == '/' && previous == '/') fail("contains '//'");
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '/')) {
      fail(std::string("contains '") + c + "' (allowed: letters, digits, '_' and '/')");
    }
    previous = c;
  }
}

// ----------------------------------------------------------------------------------------------
// Loan and Sample.

Loan::Loan(Loan&& other) noexcept
    : owner_(std::move(other.owner_)),
      slot_(other.slot_),
      data_(std::exchange(other.data_, nullptr)),
      size_(other.size_),
      capacity_(other.capacity_) {}

Loan& Loan::operator=(Loan&& other) noexcept {
  if (this != &other) {
    this->~Loan();
    new (this) Loan(std::move(other));
  }
  return *this;
}

Loan::~Loan() {
  if (data_ != nullptr && owner_) {
    owner_->Slot(slot_)->refs.fetch_sub(kLoanBit, std::memory_order_acq_rel);
  }
  data_ = nullptr;
}

void Loan::Resize(size_t bytes) {
  if (!valid()) throw BusError("Resize() on an empty loan");
  if (bytes > capacity_) {
    throw BusError("topic '" + owner_->topic->topic() + "': cannot resize a loan to " +
                   std::to_string(bytes) + " bytes, the capacity is " + std::to_string(capacity_));
  }
  size_ = bytes;
}

Sample::Sample(Sample&& other) noexcept
    : owner_(std::move(other.owner_)),
      mapping_(std::move(other.mapping_)),
      held_index_(other.held_index_),
      data_(std::exchange(other.data_, nullptr)),
      info_(other.info_) {}

Sample& Sample::operator=(Sample&& other) noexcept {
  if (this != &other) {
    Release();
    new (this) Sample(std::move(other));
  }
  return *this;
}

Sample::~Sample() { Release(); }

void Sample::Release() {
  if (data_ != nullptr && owner_) {
    try {
      owner_->Release(held_index_);
    } catch (const BusError&) {
      // Only a failing robust-mutex lock can throw here; the reference is then reclaimed with the
      // subscriber.
    }
  }
  data_ = nullptr;
  mapping_.reset();
  owner_.reset();
}

// ----------------------------------------------------------------------------------------------
// Publisher.

Publisher::Publisher(std::string_view topic, const TopicType& type,
                     const PublisherOptions& options) {
  ValidateTopicName(topic);
  const std::string t(topic);
  if (options.max_message_bytes == 0 || options.max_message_bytes > internal::kMaxMessageBytes) {
    throw BusError("topic '" + t + "': max_message_bytes must be 1.." +
                   std::to_string(internal::kMaxMessageBytes) + ", got " +
                   std::to_string(options.max_message_bytes));
  }
  if (options.history > kMaxHistory) {
    throw BusError("topic '" + t + "': history must be 0.." + std::to_string(kMaxHistory) +
                   ", got " + std::to_string(options.history));
  }
  if (options.slot_count < options.history + 2 || options.slot_count > internal::kMaxSlots) {
    throw BusError("topic '" + t + "': slot_count must be history + 2.." +
                   std::to_string(internal::kMaxSlots) + ", got " +
                   std::to_string(options.slot_count));
  }
  if (options.node_name.size() > kMaxNameLength) {
    throw BusError("topic '" + t + "': node name longer than " + std::to_string(kMaxNameLength));
  }
  const std::string domain = CurrentDomain();
  auto impl = std::make_shared<internal::PublisherImpl>();
  impl->capacity = options.max_message_bytes;
  impl->history = options.history;
  const size_t stride = internal::AlignUp(internal::kSlotHeaderBytes + impl->capacity, 64);
  const size_t bytes = internal::SlotsOffset() + stride * options.slot_count;

  // The data segment first, so a subscriber never sees a registered publisher without one.
  const internal::ProcessId& self = internal::Self();
  for (;;) {
    impl->segment_name = internal::SegmentPrefix(domain) + "p." + std::to_string(self.pid) + "." +
                         std::to_string(internal::g_publisher_counter.fetch_add(1)) + "." +
                         internal::EncodeTopic(topic);
    impl->mapping = internal::CreateSegment(impl->segment_name, bytes);
    if (impl->mapping) break;
    // A leftover of a dead process that had our pid: it cannot be in use.
    internal::UnlinkSegment(impl->segment_name);
  }
  impl->header = TopicHandle::Header(*impl->mapping);
  impl->header->magic = internal::kPublisherMagic;
  impl->header->version = internal::kLayoutVersion;
  impl->header->slot_count = options.slot_count;
  impl->header->capacity = impl->capacity;
  impl->header->stride = stride;
  impl->header->owner = self;
  impl->header->history = options.history;
  internal::InitRobustMutex(&impl->header->history_mutex);
  impl->mapping->slot_count = options.slot_count;
  impl->mapping->capacity = impl->capacity;
  impl->mapping->stride = stride;

  try {
    impl->topic = TopicHandle::Join(domain, topic, [&](TopicHandle& handle) {
      handle.CheckTypeLocked(type);
      auto* ctrl = handle.ctrl();
      bool any_free = false;
      for (const auto& e : ctrl->publishers) any_free |= e.state.load() == kFree;
      if (!any_free) {
        // Publishers that left (or crashed) but whose messages are still queued somewhere give
        // way to a live one: the oldest-joined zombie is purged.
        for (uint32_t i = 0; i < kMaxPublishersPerTopic; ++i) {
          if (ctrl->publishers[i].state.load() == internal::kZombie) {
            handle.PurgeZombieLocked(i);
            break;
          }
        }
      }
      for (uint32_t i = 0; i < kMaxPublishersPerTopic; ++i) {
        internal::PublisherEntry& e = ctrl->publishers[i];
        if (e.state.load() != kFree) continue;
        e.generation.fetch_add(1, std::memory_order_acq_rel);
        e.owner = self;
        internal::CopyText(e.segment, sizeof(e.segment), impl->segment_name);
        internal::CopyText(e.node_name, sizeof(e.node_name), options.node_name);
        e.capacity = impl->capacity;
        e.stride = stride;
        e.segment_bytes = bytes;
        e.slot_count = options.slot_count;
        e.history = options.history;
        e.published.store(0);
        e.published_bytes.store(0);
        e.last_publish_mono_ns.store(0);
        e.state.store(kActive, std::memory_order_release);
        impl->index = i;
        impl->generation = e.generation.load();
        impl->entry = &e;
        return;
      }
      throw BusError("topic '" + t + "' already has " + std::to_string(kMaxPublishersPerTopic) +
                     " publishers (the maximum)");
    });
  } catch (...) {
    internal::UnlinkSegment(impl->segment_name);
    throw;
  }
  impl_ = std::move(impl);
}

Publisher::~Publisher() = default;
Publisher::Publisher(Publisher&&) noexcept = default;
Publisher& Publisher::operator=(Publisher&&) noexcept = default;

Loan Publisher::Borrow(size_t bytes) {
  auto& impl = *impl_;
  if (bytes > impl.capacity) {
    throw BusError("topic '" + impl.topic->topic() + "': message of " + std::to_string(bytes) +
                   " bytes exceeds the publisher's max_message_bytes of " +
                   std::to_string(impl.capacity));
  }
  const uint32_t slots = impl.mapping->slot_count;
  // Bounded: every round either finds a slot or removes one queue reference of ours.
  const int max_rounds = 2 + static_cast<int>(kMaxSubscribersPerTopic * kMaxQueueDepth);
  for (int round = 0; round < max_rounds; ++round) {
    // The lowest free slot: the pool's footprint stays at the slots really in flight.
    for (uint32_t s = 0; s < slots; ++s) {
      auto& refs = impl.Slot(s)->refs;
      uint32_t expected = 0;
      if (refs.load(std::memory_order_relaxed) == 0 &&
          refs.compare_exchange_strong(expected, kLoanBit, std::memory_order_acquire)) {
        Loan loan;
        loan.owner_ = impl_;
        loan.slot_ = s;
        loan.data_ = impl.Payload(s);
        loan.size_ = bytes;
        loan.capacity_ = impl.capacity;
        return loan;
      }
    }
    if (round == 0) {
      impl.topic->Maintain();  // reclaims slots of dead subscribers
    } else if (!impl.StealOldestQueued() && impl.AuditSlots() == 0) {
      break;  // every slot is held (or loaned): nothing to drop
    }
  }
  throw BusError("topic '" + impl.topic->topic() + "': all " + std::to_string(slots) +
                 " slots of the publisher are held by subscribers' samples or unpublished loans; "
                 "raise slot_count or release samples sooner");
}

uint64_t Publisher::Publish(Loan&& loan) {
  auto& impl = *impl_;
  if (!loan.valid() || loan.owner_ != impl_) {
    throw BusError("topic '" + impl.topic->topic() +
                   "': Publish() needs a valid loan borrowed from this publisher");
  }
  const uint32_t slot = loan.slot_;
  internal::SlotHeader* header = impl.Slot(slot);
  header->size = static_cast<uint32_t>(loan.size_);
  header->sequence = ++impl.sequence;
  header->publish_wall_ns = internal::WallNowNs();
  header->publish_mono_ns = internal::MonotonicNowNs();
  loan.data_ = nullptr;  // the loan bit is handed over to this function
  loan.owner_.reset();

  internal::TopicControl* ctrl = impl.topic->ctrl();
  const QueueEntry ref{impl.index, impl.generation, slot, 0};
  {
    std::optional<RobustLock> history_lock;
    if (impl.history > 0) history_lock.emplace(&impl.header->history_mutex);
    for (auto& sub : ctrl->subscribers) {
      if (sub.state.load(std::memory_order_acquire) != kActive) continue;
      {
        RobustLock lock(&sub.mutex);
        if (sub.state.load(std::memory_order_relaxed) != kActive) continue;
        header->refs.fetch_add(1, std::memory_order_acq_rel);  // count first, then insert
        internal::PopLeadingTombstones(sub);
        if (sub.count == sub.depth) {  // drop-oldest
          const QueueEntry oldest = sub.ring[sub.head];
          sub.head = (sub.head + 1) % kMaxQueueDepth;
          sub.count -= 1;
          OrderStores();  // out of the ring before its reference is released
          if (!IsTombstone(oldest)) {
            impl.topic->DecRef(oldest);
            sub.dropped.fetch_add(1, std::memory_order_relaxed);
          }
        }
        sub.ring[(sub.head + sub.count) % kMaxQueueDepth] = ref;
        OrderStores();
        sub.count += 1;
        sub.received.fetch_add(1, std::memory_order_relaxed);
      }
      sub.futex.fetch_add(1, std::memory_order_seq_cst);
      if (sub.waiters.load(std::memory_order_seq_cst) != 0) internal::FutexWakeAll(&sub.futex);
    }
    if (impl.history > 0) {
      auto* h = impl.header;
      header->refs.fetch_add(1, std::memory_order_relaxed);
      if (h->history_count == h->history) {
        const uint32_t oldest = h->history_slots[h->history_head];
        h->history_head = (h->history_head + 1) % kMaxHistory;
        h->history_count -= 1;
        impl.Slot(oldest)->refs.fetch_sub(1, std::memory_order_acq_rel);
      }
      h->history_slots[(h->history_head + h->history_count) % kMaxHistory] = slot;
      h->history_count += 1;
    }
  }
  header->refs.fetch_sub(kLoanBit, std::memory_order_acq_rel);
  impl.entry->published.fetch_add(1, std::memory_order_relaxed);
  impl.entry->published_bytes.fetch_add(header->size, std::memory_order_relaxed);
  impl.entry->last_publish_mono_ns.store(header->publish_mono_ns, std::memory_order_relaxed);
  impl.topic->MaintainIfDue();
  return header->sequence;
}

uint64_t Publisher::PublishCopy(std::span<const std::byte> bytes) {
  Loan loan = Borrow(bytes.size());
  if (!bytes.empty()) std::memcpy(loan.data().data(), bytes.data(), bytes.size());
  return Publish(std::move(loan));
}

uint32_t Publisher::SubscriberCount() const {
  uint32_t n = 0;
  for (const auto& s : impl_->topic->ctrl()->subscribers) {
    n += s.state.load() == kActive && internal::ProbablyAlive(s.owner);
  }
  return n;
}

const std::string& Publisher::topic() const { return impl_->topic->topic(); }
size_t Publisher::max_message_bytes() const { return impl_->capacity; }

// ----------------------------------------------------------------------------------------------
// Subscriber.

Subscriber::Subscriber(std::string_view topic, const TopicType& type,
                       const SubscriberOptions& options) {
  ValidateTopicName(topic);
  const std::string t(topic);
  if (options.queue_depth < 1 || options.queue_depth > kMaxQueueDepth) {
    throw BusError("topic '" + t + "': queue_depth must be 1.." + std::to_string(kMaxQueueDepth) +
                   ", got " + std::to_string(options.queue_depth));
  }
  if (options.node_name.size() > kMaxNameLength) {
    throw BusError("topic '" + t + "': node name longer than " + std::to_string(kMaxNameLength));
  }
  auto impl = std::make_shared<internal::SubscriberImpl>();
  impl->topic = TopicHandle::Join(CurrentDomain(), topic, [&](TopicHandle& handle) {
    handle.CheckTypeLocked(type);
    auto* ctrl = handle.ctrl();
    uint32_t index = kMaxSubscribersPerTopic;
    for (uint32_t i = 0; i < kMaxSubscribersPerTopic; ++i) {
      if (ctrl->subscribers[i].state.load() == kFree) {
        index = i;
        break;
      }
    }
    if (index == kMaxSubscribersPerTopic) {
      throw BusError("topic '" + t + "' already has " + std::to_string(kMaxSubscribersPerTopic) +
                     " subscribers (the maximum)");
    }
    internal::SubscriberEntry& e = ctrl->subscribers[index];

    // Lock the history of every publisher that keeps one, so no message is both in the history we
    // copy and pushed to us by a publish running concurrently (lock order: topic < history < sub).
    struct HistorySource {
      uint32_t pub_index;
      uint32_t generation;
      std::shared_ptr<internal::Mapping> mapping;
    };
    std::vector<HistorySource> sources;
    std::vector<std::unique_ptr<RobustLock>> history_locks;
    if (options.receive_history) {
      for (uint32_t p = 0; p < kMaxPublishersPerTopic; ++p) {
        const auto& pub = ctrl->publishers[p];
        if (pub.state.load() != kActive || pub.history == 0) continue;
        auto mapping = handle.PublisherMapping(p, pub.generation.load());
        if (!mapping) continue;
        history_locks.push_back(
            std::make_unique<RobustLock>(&TopicHandle::Header(*mapping)->history_mutex));
        sources.push_back({p, pub.generation.load(), std::move(mapping)});
      }
    }
    {
      RobustLock lock(&e.mutex);
      e.owner = internal::Self();
      internal::CopyText(e.node_name, sizeof(e.node_name), options.node_name);
      e.depth = options.queue_depth;
      e.head = 0;
      e.count = 0;
      e.held_mask = 0;
      e.waiters.store(0);
      e.received.store(0);
      e.dropped.store(0);
      for (const auto& source : sources) {
        auto* h = TopicHandle::Header(*source.mapping);
        for (uint32_t i = 0; i < std::min(h->history_count, kMaxHistory); ++i) {
          const uint32_t slot = h->history_slots[(h->history_head + i) % kMaxHistory];
          if (slot >= source.mapping->slot_count) continue;  // a corrupt history entry
          TopicHandle::Slot(*source.mapping, slot)->refs.fetch_add(1, std::memory_order_acq_rel);
          if (e.count == e.depth) {
            const QueueEntry oldest = e.ring[e.head];
            e.head = (e.head + 1) % kMaxQueueDepth;
            e.count -= 1;
            OrderStores();
            handle.DecRef(oldest);
          }
          e.ring[(e.head + e.count) % kMaxQueueDepth] = {source.pub_index, source.generation, slot,
                                                         0};
          OrderStores();
          e.count += 1;
          e.received.fetch_add(1);
        }
      }
      e.state.store(kActive, std::memory_order_release);
    }
    history_locks.clear();
    impl->index = index;
    impl->entry = &e;
  });
  impl_ = std::move(impl);
}

Subscriber::~Subscriber() = default;
Subscriber::Subscriber(Subscriber&&) noexcept = default;
Subscriber& Subscriber::operator=(Subscriber&&) noexcept = default;

std::optional<Sample> Subscriber::TryTake() {
  auto& impl = *impl_;
  internal::SubscriberEntry& e = *impl.entry;
  for (;;) {
    QueueEntry ref{};
    uint32_t held_index = 0;
    {
      RobustLock lock(&e.mutex);
      if (e.count == 0) break;
      if (e.held_mask == (1u << kMaxHeldSamples) - 1) {
        throw BusError("topic '" + impl.topic->topic() + "': the subscriber already holds " +
                       std::to_string(kMaxHeldSamples) +
                       " samples; release some before taking more");
      }
      ref = e.ring[e.head];
      e.head = (e.head + 1) % kMaxQueueDepth;
      e.count -= 1;
      if (IsTombstone(ref)) continue;  // a stolen or purged entry: nothing to hand out
      OrderStores();  // out of the ring before it enters the held table (see kTombstoneSlot)
      held_index = static_cast<uint32_t>(std::countr_one(e.held_mask));
      e.held[held_index] = ref;
      OrderStores();
      e.held_mask |= 1u << held_index;
    }
    std::string why;
    auto mapping = impl.topic->PublisherMapping(ref.pub_index, ref.pub_generation, &why);
    if (!mapping || ref.slot >= mapping->slot_count) {
      // Its publisher crashed and was reclaimed (the message is gone), or a faulty publisher's
      // pool or queue entry is invalid: dropped, without touching the slot.
      RobustLock lock(&e.mutex);
      e.held_mask &= ~(1u << held_index);
      e.dropped.fetch_add(1, std::memory_order_relaxed);
      if (mapping) {
        why = "a queue entry names slot " + std::to_string(ref.slot) + " of a pool of " +
              std::to_string(mapping->slot_count);
      }
      if (!why.empty()) impl.Reject(ref.pub_index, why);
      continue;
    }
    const internal::SlotHeader* slot = TopicHandle::Slot(*mapping, ref.slot);
    if ((slot->refs.load(std::memory_order_acquire) & ~internal::kLoanBit) == 0) {
      // The entry's own reference is missing: it names a slot nobody published to us.
      RobustLock lock(&e.mutex);
      e.held_mask &= ~(1u << held_index);
      e.dropped.fetch_add(1, std::memory_order_relaxed);
      impl.Reject(ref.pub_index, "a queue entry names slot " + std::to_string(ref.slot) +
                                     ", which holds no reference");
      continue;
    }
    // Read once: the publisher may write the header again at any time.
    const uint32_t size = *static_cast<const volatile uint32_t*>(&slot->size);
    if (size > mapping->capacity) {
      impl.Release(held_index);
      e.dropped.fetch_add(1, std::memory_order_relaxed);
      impl.Reject(ref.pub_index, "slot " + std::to_string(ref.slot) + " says " +
                                     std::to_string(size) + " payload bytes, its capacity is " +
                                     std::to_string(mapping->capacity));
      continue;
    }
    Sample sample;
    sample.owner_ = impl_;
    sample.held_index_ = held_index;
    sample.data_ = reinterpret_cast<const std::byte*>(slot) + internal::kSlotHeaderBytes;
    sample.info_.sequence = slot->sequence;
    sample.info_.publish_mono_ns = slot->publish_mono_ns;
    sample.info_.publish_wall_ns = slot->publish_wall_ns;
    sample.info_.size = size;
    sample.info_.publisher_pid = TopicHandle::Header(*mapping)->owner.pid;
    sample.info_.publisher_index = ref.pub_index;
    sample.mapping_ = std::move(mapping);
    return sample;
  }
  impl.topic->MaintainIfDue();
  return std::nullopt;
}

std::optional<Sample> Subscriber::Take(std::chrono::nanoseconds timeout) {
  internal::SubscriberEntry& e = *impl_->entry;
  const int64_t deadline = internal::MonotonicNowNs() + timeout.count();
  for (;;) {
    const uint32_t seen = e.futex.load(std::memory_order_acquire);
    if (auto sample = TryTake()) return sample;
    if (internal::MonotonicNowNs() >= deadline) return std::nullopt;
    e.waiters.fetch_add(1, std::memory_order_seq_cst);
    if (e.futex.load(std::memory_order_seq_cst) == seen)
      internal::FutexWait(&e.futex, seen, deadline);
    e.waiters.fetch_sub(1, std::memory_order_seq_cst);
  }
}

uint64_t Subscriber::dropped() const { return impl_->entry->dropped.load(); }

void Subscriber::CountDownstreamDrops(uint64_t n) {
  if (n > 0) impl_->entry->dropped.fetch_add(n, std::memory_order_relaxed);
}

uint64_t Subscriber::rejected() const { return impl_->rejected; }

const std::string& Subscriber::last_rejection() const { return impl_->last_rejection; }

uint32_t Subscriber::queued() const {
  RobustLock lock(&impl_->entry->mutex);
  return internal::LiveCount(*impl_->entry);
}

uint32_t Subscriber::PublisherCount() const {
  uint32_t n = 0;
  for (const auto& p : impl_->topic->ctrl()->publishers) {
    n += p.state.load() == kActive && internal::ProbablyAlive(p.owner);
  }
  return n;
}

const std::string& Subscriber::topic() const { return impl_->topic->topic(); }

// ----------------------------------------------------------------------------------------------
// WaitSet.

size_t WaitSet::Add(Subscriber& subscriber) {
  if (subscribers_.size() >= 128) throw BusError("a WaitSet holds at most 128 subscribers");
  subscribers_.push_back(&subscriber);
  return subscribers_.size() - 1;
}

std::vector<size_t> WaitSet::Wait(std::chrono::nanoseconds timeout) {
  const int64_t deadline = internal::MonotonicNowNs() + timeout.count();
  const size_t n = subscribers_.size();
  std::vector<std::atomic<uint32_t>*> words(n);
  std::vector<uint32_t> seen(n);
  std::vector<size_t> ready;
  for (;;) {
    for (size_t i = 0; i < n; ++i) {
      words[i] = &subscribers_[i]->impl_->entry->futex;
      seen[i] = words[i]->load(std::memory_order_acquire);
    }
    for (size_t i = 0; i < n; ++i) {
      if (subscribers_[i]->queued() > 0) ready.push_back(i);
    }
    if (!ready.empty() || internal::MonotonicNowNs() >= deadline) return ready;
    for (size_t i = 0; i < n; ++i) subscribers_[i]->impl_->entry->waiters.fetch_add(1);
    bool changed = false;
    for (size_t i = 0; i < n; ++i) changed |= words[i]->load() != seen[i];
    if (!changed) internal::FutexWaitMany(words.data(), seen.data(), n, deadline);
    for (size_t i = 0; i < n; ++i) subscribers_[i]->impl_->entry->waiters.fetch_sub(1);
  }
}

}  // namespace probeless::bus
