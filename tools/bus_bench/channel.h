// bus_bench: the transports under test behind one small interface.
//
// A PubChannel publishes one topic; a SubChannel receives one topic. Every transport keeps a
// bounded per-subscriber queue that drops when full, so a slow subscriber never blocks the
// publisher (UDS: a subscriber whose socket still holds an unsent frame misses new messages).
// Loaned/received payloads are 64-byte aligned where the transport allows it (iceoryx: 8 bytes
// minimum, 64 requested).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

namespace probeless::bus_bench {

enum class Transport : uint32_t { kProbeless = 0, kUds = 1, kIceoryx = 2 };

// "probeless", "uds" or "iceoryx" (the JSON `transport` value).
const char* TransportName(Transport transport);

class PubChannel {
 public:
  virtual ~PubChannel() = default;
  // A writable buffer for a message of `bytes` (≤ the channel's max bytes), valid until Publish().
  // Throws std::runtime_error if the transport cannot hand out a buffer (pool exhausted).
  virtual std::byte* Loan(size_t bytes) = 0;
  // Publishes the loaned buffer to every connected subscriber.
  virtual void Publish() = 0;
  // Subscribers connected as far as the publisher side can tell (iceoryx: 0 or `expected`).
  virtual uint32_t Subscribers(uint32_t expected) = 0;
  // Moves queued outgoing bytes on (UDS only) until nothing is pending or CLOCK_MONOTONIC reaches
  // `deadline_ns`; `spin` polls without sleeping. Returns true if bytes are still pending.
  virtual bool Pump(int64_t deadline_ns, bool spin) { return false; }
  // Messages the transport skipped for a subscriber on the publisher side so far, summed over
  // subscribers (-1 when it does not count them there).
  virtual int64_t TransportDrops() const { return -1; }
};

class SubChannel {
 public:
  virtual ~SubChannel() = default;
  // The next message: blocks up to `timeout_ns` when `block`, else returns at once. An empty span
  // means nothing arrived. The view stays valid until Release() or the next Receive().
  virtual std::span<const std::byte> Receive(bool block, int64_t timeout_ns) = 0;
  // Gives the last received message back to the transport.
  virtual void Release() = 0;
  // True once the subscription is established (messages published from now on are delivered).
  virtual bool Connected() = 0;
  // True while a message is partly received (UDS stream framing); false for shared memory.
  virtual bool InMessage() const { return false; }
  // Drops the transport itself counted for this subscriber (-1 when it does not count them).
  virtual int64_t TransportDrops() const { return -1; }
};

// Identifies a topic of a benchmark session: every name derives from `run_id` (unique per
// session) and the publisher/topic indices.
struct TopicId {
  std::string run_id;
  uint32_t publisher = 0;
  uint32_t topic = 0;
};

std::unique_ptr<PubChannel> MakeProbelessPub(const TopicId& id, size_t max_bytes);
std::unique_ptr<SubChannel> MakeProbelessSub(const TopicId& id, uint32_t queue_depth);

std::unique_ptr<PubChannel> MakeUdsPub(const TopicId& id, size_t max_bytes, uint32_t subscribers);
std::unique_ptr<SubChannel> MakeUdsSub(const TopicId& id, size_t max_bytes);

// True if bus_bench was built with iceoryx (BUS_BENCH_HAVE_ICEORYX).
bool IceoryxAvailable();
// Registers this process with RouDi under `name` (once per process, before any channel).
void InitIceoryxRuntime(const std::string& name);
std::unique_ptr<PubChannel> MakeIceoryxPub(const TopicId& id, size_t max_bytes);
std::unique_ptr<SubChannel> MakeIceoryxSub(const TopicId& id, uint32_t queue_depth);

}  // namespace probeless::bus_bench
