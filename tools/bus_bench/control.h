// bus_bench: the control block shared by the orchestrator and its publisher/subscriber processes.
//
// The orchestrator creates it in a memfd that the role processes inherit across exec
// (`--ctl-fd`); nothing of it appears in /dev/shm. Phases run in lock step: the orchestrator fills
// `phase`, bumps `go`; subscribers report `ready_sub`, publishers publish and set `done_pub`,
// subscribers drain and set `done_sub`. Every state change bumps `events` and wakes its futex.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "channel.h"

namespace probeless::bus_bench {

inline constexpr uint32_t kMaxPubs = 4;
inline constexpr uint32_t kMaxSubs = 4;
inline constexpr uint32_t kMaxTopicsPerPub = 2;
inline constexpr uint32_t kMaxTopics = kMaxPubs * kMaxTopicsPerPub;
inline constexpr uint32_t kMaxRecords = 1u << 15;      // latency samples per subscriber and phase
inline constexpr uint32_t kMessageMagic = 0x42424D31;  // "BBM1"
inline constexpr size_t kHeaderBytes = 64;  // the message header at the start of every payload
// Sequence number of the header-only message that ends a publisher's phase on a topic. Being the
// newest, drop-oldest queues never drop it, and subscribers need no short wake-up timeouts to
// notice the end (a 2 ms timeout costs ~8 us per wake-up here: the timer is re-armed each time).
inline constexpr uint32_t kEndMarker = 0xFFFFFFFF;

// The first bytes of every message. `stamp_ns` is CLOCK_MONOTONIC written just before Publish.
struct MessageHeader {
  uint32_t magic = kMessageMagic;
  uint32_t phase = 0;
  uint32_t seq = 0;    // 1, 2, … per topic and phase
  uint32_t topic = 0;  // global topic index: publisher * topics_per_pub + topic
  uint32_t size = 0;   // payload bytes
  uint32_t fill = 0;   // the byte value of payload bytes [kHeaderBytes, size) when written
  int64_t stamp_ns = 0;
};
static_assert(sizeof(MessageHeader) <= kHeaderBytes);

// One measurement phase (all times CLOCK_MONOTONIC nanoseconds).
struct Phase {
  uint32_t id = 0;  // 1, 2, …; 0 never runs
  uint32_t quit = 0;
  uint32_t busy = 0;           // subscribers poll (TryTake loop) instead of blocking (Take)
  uint32_t write_payload = 0;  // publisher fills and subscriber checksums every byte
  uint32_t sizes[kMaxTopicsPerPub] = {};
  uint32_t count = 0;       // messages per topic (unpaced: upper bound)
  uint32_t warmup = 0;      // sequence numbers ≤ warmup are left out of latency statistics
  int64_t period_ns = 0;    // pacing; 0 = unpaced (throughput)
  int64_t duration_ns = 0;  // unpaced: publish for this long
  int64_t stagger_ns = 0;   // publisher i starts i * stagger_ns later (unsynchronised cameras)
  uint32_t window = 0;      // unpaced: at most this many messages ahead of every fast subscriber
  uint32_t slow_mask = 0;   // subscribers that sleep slow_sleep_ns per message (holding it)
  int64_t slow_sleep_ns = 0;
};

struct LatencyRecord {
  int64_t latency_ns = 0;
  uint32_t topic = 0;
  uint32_t seq = 0;
};

struct PubResult {
  uint32_t attempted[kMaxTopicsPerPub] = {};  // messages the publisher tried to send
  uint32_t sent[kMaxTopicsPerPub] = {};       // … and sent (a failed loan is not sent)
  uint32_t loan_failures = 0;
  // Messages the transport itself skipped on the publisher side (UDS: drop-newest while a frame
  // is still pending), summed over subscribers; -1 if it does not count them there.
  int64_t transport_drops[kMaxTopicsPerPub] = {};
  int64_t first_stamp_ns = 0;
  int64_t last_stamp_ns = 0;
  int64_t max_publish_ns = 0;  // longest Loan + Publish call (payload filling excluded)
  int64_t max_late_ns = 0;     // worst pacing lateness
  // Longest time from the pacing wake-up to the header stamp (loan + payload fill): consecutive
  // stamps of a paced phase are at least (period - max_fill_ns) apart.
  int64_t max_fill_ns = 0;
};

struct SubResult {
  std::atomic<uint32_t> n_records{0};
  uint32_t received[kMaxTopics] = {};
  uint32_t checksum_errors[kMaxTopics] = {};
  uint32_t stale[kMaxTopics] = {};
  // Messages whose sequence number was not above the one taken before on the topic (a duplicate
  // or out of order): the transport broke ordering or integrity (target 0).
  uint32_t reordered[kMaxTopics] = {};
  int64_t transport_drops[kMaxTopics] = {};  // as counted by the transport, -1 if it does not
  int64_t first_recv_ns[kMaxTopics] = {};
  int64_t last_recv_ns[kMaxTopics] = {};
  // Longest interval between two consecutive takes of the topic (the end marker included): a
  // subscriber that took nothing for (queue depth) periods of a paced phase was itself slow then.
  int64_t max_gap_ns[kMaxTopics] = {};
  // Time the receiving threads waited on a run queue (runnable, not running) during the phase,
  // from /proc/thread-self/schedstat; -1 if the kernel does not provide it. Separates a
  // subscriber descheduled by other load from one the transport failed to wake.
  std::atomic<int64_t> run_delay_ns{0};
  LatencyRecord records[kMaxRecords];
};

struct Control {
  // Session configuration, fixed before the role processes start.
  Transport transport = Transport::kProbeless;
  uint32_t n_pubs = 1;
  uint32_t n_subs = 1;
  uint32_t topics_per_pub = 1;
  uint64_t max_bytes = 0;
  uint32_t queue_depth = 4;
  int32_t pub_cpu[kMaxPubs] = {-1, -1, -1, -1};
  int32_t sub_cpu[kMaxSubs] = {-1, -1, -1, -1};
  uint32_t realtime = 0;  // SCHED_FIFO roles (busy-poll subscribers: SCHED_OTHER, nice -20)
  char run_id[48] = {};

  std::atomic<uint32_t> events{0};  // bumped (and futex-woken) on every state change below
  std::atomic<uint32_t> go{0};      // == phase.id once the phase is released
  Phase phase;
  std::atomic<uint32_t> connected_pub[kMaxPubs] = {};
  std::atomic<uint32_t> connected_sub[kMaxSubs] = {};
  std::atomic<uint32_t> ready_sub[kMaxSubs] = {};  // phase id the subscriber receives
  std::atomic<uint32_t> done_pub[kMaxPubs] = {};
  std::atomic<uint32_t> done_sub[kMaxSubs] = {};
  std::atomic<uint32_t> exited[kMaxPubs + kMaxSubs] = {};

  // Flow control of unpaced phases: messages taken per subscriber in the current phase.
  std::atomic<uint64_t> acked[kMaxSubs] = {};
  std::atomic<uint32_t> ack_futex{0};
  std::atomic<uint32_t> pub_waiting{0};

  std::atomic<uint32_t> failed{0};
  char error[512] = {};

  PubResult pubs[kMaxPubs];
  SubResult subs[kMaxSubs];
};

int64_t MonoNs();
void FutexWait(std::atomic<uint32_t>* word, uint32_t expected, int64_t timeout_ns);
void FutexWake(std::atomic<uint32_t>* word);
// Bumps `events` and wakes everyone waiting for a state change.
void Signal(Control& control);
// Records the first failure of any process (one line) and signals.
void ReportFailure(Control& control, const std::string& what);
// Pins the calling thread to `cpu` (no-op for cpu < 0).
void PinToCpu(int cpu);
// Scheduling of the calling thread: SCHED_FIFO priority kRealtimePriority, or SCHED_OTHER with
// `nice`. Returns false if not permitted.
inline constexpr int kRealtimePriority = 50;
bool SetRealtime(bool fifo, int nice = 0);

// The payload byte of message `seq` on `topic` (never 0, so an unwritten page never matches).
uint32_t FillByte(uint32_t seq, uint32_t topic);
// True if every byte of payload[kHeaderBytes, size) equals `fill` (reads every byte).
bool PayloadMatches(std::span<const std::byte> payload, uint32_t fill);

// Run-queue wait of the calling thread so far in nanoseconds (schedstat), -1 if unavailable.
int64_t ThreadRunDelayNs();

// Role process entry points (`bus_bench --role pub|sub --ctl-fd N --index I`); return exit codes.
int RunPublisherRole(Control& control, uint32_t index);
int RunSubscriberRole(Control& control, uint32_t index);

}  // namespace probeless::bus_bench
