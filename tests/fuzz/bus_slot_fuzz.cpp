// libFuzzer target: a bus subscriber reading a message whose shared memory a faulty or hostile
// publisher wrote (issue #22). Per input a fresh publisher (4 slots of 256 bytes) publishes one
// 100-byte message to a subscriber of this process, the input then overwrites part of what the
// subscriber is about to read, and the subscriber takes everything queued. The first byte picks
// what the rest overwrites (mod 4):
//   0  the slot: its header after the reference count (size, sequence, stamps) and the payload;
//   1  the pool header's geometry (magic, version, slot count, capacity, stride) before the
//      subscriber maps the pool;
//   2  the slot index of the subscriber's queue entry;
//   3  the whole queue entry (publisher index, generation, slot).
// Contract: no crash, no escaped exception; a sample handed out lies inside its slot (size <= the
// capacity, every byte readable); the message is delivered or counted in dropped() (a message is
// rejected, i.e. dropped with last_rejection() naming why, when its size, pool or entry is
// invalid), except when the entry was overwritten with the tombstone marker (nothing queued).
// Not covered: the reference counts (the crash-recovery protocol, bus_chaos_test), and a pool
// segment shrunk by its publisher after the subscriber mapped it (SIGBUS, docs/bus.md "Limits").
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>

#include "fuzz_file.h"
#include "probeless/bus/bus.h"
#include "shm.h"
#include "shm_layout.h"

namespace {

namespace bus = probeless::bus;
namespace internal = probeless::bus::internal;
using probeless::fuzz::Check;

constexpr char kTopic[] = "/fuzz/slot";
constexpr size_t kCapacity = 256;
constexpr size_t kMessage = 100;
const bus::TopicType kType{"probeless_fuzz/Bytes", 0x5eed};

struct Fixture {
  Fixture() {
    // A domain of its own: no other process' topics, and ours are gone with the process.
    ::setenv("PROBELESS_DOMAIN", ("bus_slot_fuzz_" + std::to_string(::getpid())).c_str(), 1);
    subscriber = std::make_unique<bus::Subscriber>(kTopic, kType, bus::SubscriberOptions{4});
    control = internal::OpenSegment(internal::TopicSegmentName(bus::CurrentDomain(), kTopic), 0);
    Check(control != nullptr);
  }
  ~Fixture() {
    subscriber.reset();
    bus::CleanDeadSegments();
  }
  // The subscriber's entry in the topic registry.
  internal::SubscriberEntry& Entry() const {
    auto* ctrl = reinterpret_cast<internal::TopicControl*>(control->base());
    for (auto& e : ctrl->subscribers) {
      if (e.state.load() == internal::kActive && e.owner.pid == ::getpid()) return e;
    }
    std::abort();
  }
  std::unique_ptr<bus::Subscriber> subscriber;
  std::shared_ptr<internal::Mapping> control;
};

void Overwrite(void* at, size_t room, const uint8_t* data, size_t size) {
  std::memcpy(at, data, size < room ? size : room);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static Fixture fixture;
  if (size < 1 || size > 4096) return 0;
  const int mode = data[0] % 4;
  const uint8_t* rest = data + 1;
  const size_t rest_size = size - 1;
  bus::Subscriber& sub = *fixture.subscriber;
  const uint64_t dropped_before = sub.dropped();
  const uint64_t rejected_before = sub.rejected();
  bool tombstone = false;
  try {
    bus::PublisherOptions options;
    options.max_message_bytes = kCapacity;
    options.slot_count = 4;
    bus::Publisher pub(kTopic, kType, options);
    bus::Loan loan = pub.Borrow(kMessage);
    std::memset(loan.data().data(), 0xab, kMessage);
    // The lowest free slot of a fresh pool is slot 0: the pool starts SlotsOffset() before it.
    std::byte* payload = loan.data().data();
    auto* slot = reinterpret_cast<internal::SlotHeader*>(payload - internal::kSlotHeaderBytes);
    auto* pool = reinterpret_cast<internal::PublisherHeader*>(reinterpret_cast<std::byte*>(slot) -
                                                              internal::SlotsOffset());
    Check(pool->magic == internal::kPublisherMagic);
    pub.Publish(std::move(loan));

    if (mode == 1) {
      Overwrite(pool, 32, rest, rest_size);  // magic, version, slot_count, capacity, stride
    }
    if (mode == 0) {
      // After the reference count: the rest of the header, then the payload.
      Overwrite(reinterpret_cast<std::byte*>(slot) + 4, internal::kSlotHeaderBytes - 4 + kCapacity,
                rest, rest_size);
    }
    if (mode == 2 || mode == 3) {
      internal::SubscriberEntry& e = fixture.Entry();
      Check(e.count >= 1);
      internal::QueueEntry& q = e.ring[(e.head + e.count - 1) % bus::kMaxQueueDepth];
      if (mode == 2) {
        Overwrite(&q.slot, 4, rest, rest_size);
      } else {
        Overwrite(&q, 12, rest, rest_size);
      }
      tombstone = internal::IsTombstone(q);
    }

    uint64_t delivered = 0;
    while (auto sample = sub.TryTake()) {
      Check(sample->data().size() <= kCapacity);
      Check(sample->info().size == sample->data().size());
      unsigned sum = 0;
      for (std::byte b : sample->data()) sum += static_cast<unsigned>(b);  // every byte readable
      Check(sum <= 255u * kCapacity);
      ++delivered;
    }
    const uint64_t dropped = sub.dropped() - dropped_before;
    Check(delivered + dropped == (tombstone ? 0u : 1u));
    if (sub.rejected() > rejected_before) {
      Check(sub.rejected() - rejected_before == 1 && dropped == 1);
      Check(sub.last_rejection().rfind("topic '/fuzz/slot': message of ", 0) == 0);
    }
  } catch (const bus::BusError&) {
    // Rejected with a message: the contract.
  }
  return 0;
}
