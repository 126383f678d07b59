// A faulty or hostile publisher's shared memory as a subscriber reads it (issue #22; the fuzzer
// is tests/fuzz/bus_slot_fuzz.cpp): a slot size beyond the capacity, a pool header that is no
// pool of its segment, a queue entry naming a slot outside the pool or one without a reference:
// the message is dropped and counted, rejected() and last_rejection() say why, nothing outside
// the slot is handed out, and the next good message arrives.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <string>

#include "probeless/bus/bus.h"
#include "shm.h"
#include "shm_layout.h"

namespace probeless::bus {
namespace {

const TopicType kType{"probeless_test/Bytes", 7};
constexpr char kTopic[] = "/fault/slot";

class SlotFault : public ::testing::Test {
 protected:
  SlotFault() {
    ::setenv("PROBELESS_DOMAIN", ("slot_fault_" + std::to_string(::getpid())).c_str(), 1);
  }
  PublisherOptions Options() const {
    PublisherOptions o;
    o.max_message_bytes = 256;
    o.slot_count = 4;
    return o;
  }
  // Publishes `bytes` bytes of 7s; returns the slot header (slot 0 of a fresh pool).
  static internal::SlotHeader* PublishOne(Publisher& pub, size_t bytes) {
    Loan loan = pub.Borrow(bytes);
    std::memset(loan.data().data(), 7, bytes);
    auto* slot =
        reinterpret_cast<internal::SlotHeader*>(loan.data().data() - internal::kSlotHeaderBytes);
    pub.Publish(std::move(loan));
    return slot;
  }
  static internal::PublisherHeader* Pool(internal::SlotHeader* slot0) {
    return reinterpret_cast<internal::PublisherHeader*>(reinterpret_cast<std::byte*>(slot0) -
                                                        internal::SlotsOffset());
  }
  // The newest queue entry of this process' subscriber.
  internal::QueueEntry& NewestEntry() {
    if (!control_) {
      control_ = internal::OpenSegment(internal::TopicSegmentName(CurrentDomain(), kTopic), 0);
    }
    auto* ctrl = reinterpret_cast<internal::TopicControl*>(control_->base());
    for (auto& e : ctrl->subscribers) {
      if (e.state.load() == internal::kActive && e.owner.pid == ::getpid()) {
        return e.ring[(e.head + e.count - 1) % kMaxQueueDepth];
      }
    }
    std::abort();
  }
  std::string Prefix() const {
    return "topic '/fault/slot': message of publisher pid " + std::to_string(::getpid()) +
           " dropped: ";
  }
  std::shared_ptr<internal::Mapping> control_;
};

TEST_F(SlotFault, ASizeBeyondTheCapacityIsRejected) {
  Subscriber sub(kTopic, kType, {.queue_depth = 4});
  Publisher pub(kTopic, kType, Options());
  internal::SlotHeader* slot = PublishOne(pub, 100);
  slot->size = 1000;
  EXPECT_FALSE(sub.TryTake().has_value());
  EXPECT_EQ(sub.rejected(), 1u);
  EXPECT_EQ(sub.dropped(), 1u);
  EXPECT_EQ(sub.last_rejection(), Prefix() + "slot 0 says 1000 payload bytes, its capacity is 256");
  // The capacity itself is a valid size; the slot was released and is reused.
  slot = PublishOne(pub, 100);
  slot->size = 256;
  auto sample = sub.TryTake();
  ASSERT_TRUE(sample.has_value());
  EXPECT_EQ(sample->data().size(), 256u);
  EXPECT_EQ(sub.rejected(), 1u);
}

TEST_F(SlotFault, APoolHeaderThatIsNoPoolOfItsSegmentIsRejected) {
  Subscriber sub(kTopic, kType, {.queue_depth = 4});
  {
    Publisher pub(kTopic, kType, Options());
    Pool(PublishOne(pub, 100))->stride = uint64_t{1} << 40;  // before the subscriber maps it
    EXPECT_FALSE(sub.TryTake().has_value());
    EXPECT_EQ(sub.last_rejection(),
              Prefix() +
                  "its pool header says 4 slots of 256 bytes (stride 1099511627776), "
                  "which is not a pool of its 5376-byte segment");
  }
  {
    Publisher pub(kTopic, kType, Options());
    Pool(PublishOne(pub, 100))->magic = 0;
    EXPECT_FALSE(sub.TryTake().has_value());
    EXPECT_EQ(sub.last_rejection(),
              Prefix() + "its pool segment is not a publisher pool of layout version 1");
  }
  EXPECT_EQ(sub.rejected(), 2u);
  EXPECT_EQ(sub.dropped(), 2u);
  Publisher good(kTopic, kType, Options());
  PublishOne(good, 10);
  auto sample = sub.TryTake();
  ASSERT_TRUE(sample.has_value());
  EXPECT_EQ(sample->data().size(), 10u);
}

TEST_F(SlotFault, AQueueEntryNamingNoSlotOfThePoolIsRejected) {
  Subscriber sub(kTopic, kType, {.queue_depth = 4});
  Publisher pub(kTopic, kType, Options());
  PublishOne(pub, 100);
  NewestEntry().slot = 9;
  EXPECT_FALSE(sub.TryTake().has_value());
  EXPECT_EQ(sub.last_rejection(), Prefix() + "a queue entry names slot 9 of a pool of 4");
  PublishOne(pub, 100);
  NewestEntry().slot = 3;  // a slot nobody published
  EXPECT_FALSE(sub.TryTake().has_value());
  EXPECT_EQ(sub.last_rejection(),
            Prefix() + "a queue entry names slot 3, which holds no reference");
  PublishOne(pub, 100);
  NewestEntry().pub_index = 200;
  EXPECT_FALSE(sub.TryTake().has_value());
  EXPECT_EQ(sub.last_rejection(),
            "topic '/fault/slot': message of an unknown publisher dropped: a queue entry names "
            "publisher 200");
  EXPECT_EQ(sub.rejected(), 3u);
  EXPECT_EQ(sub.dropped(), 3u);
}

}  // namespace
}  // namespace probeless::bus
