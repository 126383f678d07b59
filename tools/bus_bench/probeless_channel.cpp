// bus_bench transport: the probeless shared-memory bus (zero copy, Borrow/Publish, Take/TryTake).
#include <chrono>
#include <optional>

#include "channel.h"
#include "probeless/bus/bus.h"

namespace probeless::bus_bench {
namespace {

const bus::TopicType kBlobType{"bus_bench/Blob", 0xB0B0'0001};

std::string TopicName(const TopicId& id) {
  return "/bus_bench/r" + id.run_id + "/p" + std::to_string(id.publisher) + "_t" +
         std::to_string(id.topic);
}

class ProbelessPub final : public PubChannel {
 public:
  ProbelessPub(const TopicId& id, size_t max_bytes)
      : publisher_(TopicName(id), kBlobType,
                   bus::PublisherOptions{.max_message_bytes = max_bytes,
                                         .slot_count = 32,
                                         .history = 0,
                                         .node_name = "/bus_bench_pub"}) {}

  std::byte* Loan(size_t bytes) override {
    loan_ = publisher_.Borrow(bytes);
    return loan_.data().data();
  }
  void Publish() override { publisher_.Publish(std::move(loan_)); }
  uint32_t Subscribers(uint32_t) override { return publisher_.SubscriberCount(); }

 private:
  bus::Publisher publisher_;
  bus::Loan loan_;
};

class ProbelessSub final : public SubChannel {
 public:
  ProbelessSub(const TopicId& id, uint32_t queue_depth)
      : subscriber_(TopicName(id), kBlobType,
                    bus::SubscriberOptions{.queue_depth = queue_depth,
                                           .receive_history = false,
                                           .node_name = "/bus_bench_sub"}) {}

  std::span<const std::byte> Receive(bool block, int64_t timeout_ns) override {
    sample_.reset();
    sample_ =
        block ? subscriber_.Take(std::chrono::nanoseconds(timeout_ns)) : subscriber_.TryTake();
    if (!sample_) return {};
    return sample_->data();
  }
  void Release() override { sample_.reset(); }
  bool Connected() override { return true; }  // registered in the constructor
  int64_t TransportDrops() const override { return static_cast<int64_t>(subscriber_.dropped()); }

 private:
  bus::Subscriber subscriber_;
  std::optional<bus::Sample> sample_;
};

}  // namespace

std::unique_ptr<PubChannel> MakeProbelessPub(const TopicId& id, size_t max_bytes) {
  return std::make_unique<ProbelessPub>(id, max_bytes);
}

std::unique_ptr<SubChannel> MakeProbelessSub(const TopicId& id, uint32_t queue_depth) {
  return std::make_unique<ProbelessSub>(id, queue_depth);
}

}  // namespace probeless::bus_bench
