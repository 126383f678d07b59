// bus_bench transport: iceoryx 2.0 (RouDi-managed shared memory, loan API, untyped endpoints).
// The only file that includes iceoryx headers; without BUS_BENCH_HAVE_ICEORYX it provides stubs.
#include <stdexcept>

#include "channel.h"

#ifdef BUS_BENCH_HAVE_ICEORYX
#include "iceoryx_hoofs/log/logmanager.hpp"
#include "iceoryx_posh/mepoo/chunk_header.hpp"
#include "iceoryx_posh/popo/untyped_publisher.hpp"
#include "iceoryx_posh/popo/untyped_subscriber.hpp"
#include "iceoryx_posh/popo/wait_set.hpp"
#include "iceoryx_posh/runtime/posh_runtime.hpp"
#endif

namespace probeless::bus_bench {

#ifdef BUS_BENCH_HAVE_ICEORYX
namespace {

iox::capro::ServiceDescription Service(const TopicId& id) {
  const std::string instance = "r" + id.run_id;
  const std::string event = "p" + std::to_string(id.publisher) + "_t" + std::to_string(id.topic);
  return {iox::capro::IdString_t(iox::cxx::TruncateToCapacity, "bus_bench"),
          iox::capro::IdString_t(iox::cxx::TruncateToCapacity, instance.c_str()),
          iox::capro::IdString_t(iox::cxx::TruncateToCapacity, event.c_str())};
}

class IceoryxPub final : public PubChannel {
 public:
  IceoryxPub(const TopicId& id, size_t max_bytes) : publisher_(Service(id), Options()) {}

  std::byte* Loan(size_t bytes) override {
    auto result = publisher_.loan(static_cast<uint32_t>(bytes), 64);
    if (result.has_error()) {
      throw std::runtime_error(
          "iceoryx: loan of " + std::to_string(bytes) + " bytes failed (allocation error " +
          std::to_string(static_cast<int>(result.get_error())) + "; mempools too small?)");
    }
    chunk_ = result.value();
    return static_cast<std::byte*>(chunk_);
  }
  void Publish() override {
    publisher_.publish(chunk_);
    chunk_ = nullptr;
  }
  uint32_t Subscribers(uint32_t expected) override {
    return publisher_.hasSubscribers() ? expected : 0;
  }

 private:
  static iox::popo::PublisherOptions Options() {
    iox::popo::PublisherOptions options;
    options.historyCapacity = 0;
    options.subscriberTooSlowPolicy = iox::popo::ConsumerTooSlowPolicy::DISCARD_OLDEST_DATA;
    return options;
  }

  iox::popo::UntypedPublisher publisher_;
  void* chunk_ = nullptr;
};

class IceoryxSub final : public SubChannel {
 public:
  IceoryxSub(const TopicId& id, uint32_t queue_depth)
      : subscriber_(Service(id), Options(queue_depth)) {
    if (waitset_.attachState(subscriber_, iox::popo::SubscriberState::HAS_DATA).has_error()) {
      throw std::runtime_error("iceoryx: cannot attach the subscriber to a WaitSet");
    }
  }
  ~IceoryxSub() override {
    Release();
    waitset_.detachState(subscriber_, iox::popo::SubscriberState::HAS_DATA);
  }

  std::span<const std::byte> Receive(bool block, int64_t timeout_ns) override {
    Release();
    auto result = subscriber_.take();
    if (result.has_error() && block) {
      waitset_.timedWait(iox::units::Duration::fromNanoseconds(static_cast<uint64_t>(timeout_ns)));
      result = subscriber_.take();
    }
    if (result.has_error()) return {};
    chunk_ = result.value();
    const auto* header = iox::mepoo::ChunkHeader::fromUserPayload(chunk_);
    return {static_cast<const std::byte*>(chunk_), header->userPayloadSize()};
  }
  void Release() override {
    if (chunk_ != nullptr) subscriber_.release(chunk_);
    chunk_ = nullptr;
  }
  bool Connected() override {
    return subscriber_.getSubscriptionState() == iox::SubscribeState::SUBSCRIBED;
  }

 private:
  static iox::popo::SubscriberOptions Options(uint32_t queue_depth) {
    iox::popo::SubscriberOptions options;
    options.queueCapacity = queue_depth;
    options.historyRequest = 0;
    options.queueFullPolicy = iox::popo::QueueFullPolicy::DISCARD_OLDEST_DATA;
    return options;
  }

  iox::popo::UntypedSubscriber subscriber_;
  iox::popo::WaitSet<> waitset_;
  const void* chunk_ = nullptr;
};

}  // namespace

bool IceoryxAvailable() { return true; }

void InitIceoryxRuntime(const std::string& name) {
  // Only warnings and errors: the role processes share bus_bench's stdout.
  iox::log::LogManager::GetLogManager().SetDefaultLogLevel(iox::log::LogLevel::kWarn,
                                                           iox::log::LogLevelOutput::kHideLogLevel);
  iox::runtime::PoshRuntime::initRuntime(
      iox::RuntimeName_t(iox::cxx::TruncateToCapacity, name.c_str()));
}

std::unique_ptr<PubChannel> MakeIceoryxPub(const TopicId& id, size_t max_bytes) {
  return std::make_unique<IceoryxPub>(id, max_bytes);
}

std::unique_ptr<SubChannel> MakeIceoryxSub(const TopicId& id, uint32_t queue_depth) {
  return std::make_unique<IceoryxSub>(id, queue_depth);
}

#else  // !BUS_BENCH_HAVE_ICEORYX

bool IceoryxAvailable() { return false; }

void InitIceoryxRuntime(const std::string&) {
  throw std::runtime_error("bus_bench was built without iceoryx");
}

std::unique_ptr<PubChannel> MakeIceoryxPub(const TopicId&, size_t) {
  throw std::runtime_error("bus_bench was built without iceoryx");
}

std::unique_ptr<SubChannel> MakeIceoryxSub(const TopicId&, uint32_t) {
  throw std::runtime_error("bus_bench was built without iceoryx");
}

#endif

}  // namespace probeless::bus_bench
