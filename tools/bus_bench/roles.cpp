// bus_bench: the publisher and subscriber role processes.
#include <linux/futex.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <climits>
#include <cstring>
#include <ctime>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <thread>
#include <vector>

#include "control.h"

namespace probeless::bus_bench {

int64_t MonoNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

void FutexWait(std::atomic<uint32_t>* word, uint32_t expected, int64_t timeout_ns) {
  if (timeout_ns <= 0) return;
  const timespec timeout{timeout_ns / 1'000'000'000, timeout_ns % 1'000'000'000};
  // Shared futex (no FUTEX_PRIVATE_FLAG): the word lives in memory shared between processes.
  syscall(SYS_futex, reinterpret_cast<uint32_t*>(word), FUTEX_WAIT, expected, &timeout, nullptr, 0);
}

void FutexWake(std::atomic<uint32_t>* word) {
  syscall(SYS_futex, reinterpret_cast<uint32_t*>(word), FUTEX_WAKE, INT_MAX, nullptr, nullptr, 0);
}

void Signal(Control& control) {
  control.events.fetch_add(1, std::memory_order_seq_cst);
  FutexWake(&control.events);
}

void ReportFailure(Control& control, const std::string& what) {
  uint32_t expected = 0;
  if (control.failed.compare_exchange_strong(expected, 1)) {
    std::snprintf(control.error, sizeof(control.error), "%s", what.c_str());
  }
  Signal(control);
}

void PinToCpu(int cpu) {
  if (cpu < 0) return;
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  sched_setaffinity(0, sizeof(set), &set);
}

bool SetRealtime(bool fifo, int nice) {
  sched_param param{};
  param.sched_priority = fifo ? kRealtimePriority : 0;
  if (sched_setscheduler(0, fifo ? SCHED_FIFO : SCHED_OTHER, &param) != 0) return false;
  // The nice value of this thread only (Linux: setpriority on a thread id).
  return fifo || setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), nice) == 0;
}

uint32_t FillByte(uint32_t seq, uint32_t topic) { return 1 + (seq * 131 + topic * 7) % 255; }

bool PayloadMatches(std::span<const std::byte> payload, uint32_t fill) {
  if (payload.size() < kHeaderBytes) return false;
  const std::byte* p = payload.data() + kHeaderBytes;
  const size_t n = payload.size() - kHeaderBytes;
  const size_t words = n / 8;
  // Sum of 64-bit words plus the tail bytes, compared with what a uniform fill gives: every byte
  // is read, and the loop vectorises.
  uint64_t sum = 0;
  for (size_t i = 0; i < words; ++i) {
    uint64_t w;
    std::memcpy(&w, p + i * 8, 8);
    sum += w;
  }
  uint64_t tail = 0;
  for (size_t i = words * 8; i < n; ++i) tail += static_cast<uint8_t>(p[i]);
  const uint64_t pattern = uint64_t{fill} * 0x0101010101010101ull;
  return sum == pattern * words && tail == uint64_t{fill} * (n - words * 8);
}

int64_t ThreadRunDelayNs() {
  // "time on CPU, time waiting on a run queue, time slices" (Documentation/scheduler/sched-stats).
  std::ifstream in("/proc/thread-self/schedstat");
  int64_t on_cpu = 0, waiting = 0;
  if (!(in >> on_cpu >> waiting)) return -1;
  return waiting;
}

namespace {

constexpr int64_t kConnectTimeoutNs = 20'000'000'000;
// Take() timeout: long, so that no timer is armed near the next message (re-arming the earliest
// timer costs VM exits); the phase ends with an end marker, the loop re-checks state on timeout.
constexpr int64_t kBlockingTimeoutNs = 100'000'000;

// Waits until `done()` holds, sleeping on the events futex.
template <typename F>
bool WaitEvent(Control& c, F done, int64_t timeout_ns) {
  const int64_t deadline = MonoNs() + timeout_ns;
  for (;;) {
    const uint32_t seen = c.events.load(std::memory_order_seq_cst);
    if (done()) return true;
    if (c.failed.load()) throw std::runtime_error("another process failed");
    const int64_t left = deadline - MonoNs();
    if (left <= 0) return false;
    FutexWait(&c.events, seen, std::min<int64_t>(left, 100'000'000));
  }
}

void SleepUntil(int64_t t_ns) {
  const timespec ts{t_ns / 1'000'000'000, t_ns % 1'000'000'000};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

std::string RuntimeName(const Control& c, const char* role, uint32_t index) {
  return std::string("bus_bench_") + c.run_id + "_" + role + std::to_string(index);
}

TopicId Topic(const Control& c, uint32_t global_topic) {
  return {c.run_id, global_topic / c.topics_per_pub, global_topic % c.topics_per_pub};
}

// Waits for the next phase; returns it (quit set when the session ends).
Phase NextPhase(Control& c, uint32_t last) {
  while (!WaitEvent(
      c, [&] { return c.go.load(std::memory_order_acquire) != last; }, 3'600'000'000'000)) {
  }
  return c.phase;
}

// --- Publisher -----------------------------------------------------------------------------------

class PublisherRole {
 public:
  PublisherRole(Control& c, uint32_t index) : c_(c), index_(index) {
    for (uint32_t t = 0; t < c.topics_per_pub; ++t) {
      const TopicId id = Topic(c, index * c.topics_per_pub + t);
      switch (c.transport) {
        case Transport::kProbeless:
          channels_.push_back(MakeProbelessPub(id, c.max_bytes));
          break;
        case Transport::kUds:
          channels_.push_back(MakeUdsPub(id, c.max_bytes, c.n_subs));
          break;
        case Transport::kIceoryx:
          channels_.push_back(MakeIceoryxPub(id, c.max_bytes));
          break;
      }
    }
  }

  void Run() {
    const bool connected = WaitEvent(
        c_,
        [&] {
          for (uint32_t s = 0; s < c_.n_subs; ++s) {
            if (!c_.connected_sub[s].load()) return false;
          }
          for (auto& ch : channels_) {
            if (ch->Subscribers(c_.n_subs) < c_.n_subs) return false;
          }
          return true;
        },
        kConnectTimeoutNs);
    if (!connected) throw std::runtime_error("publisher: subscribers did not connect within 20 s");
    c_.connected_pub[index_].store(1);
    Signal(c_);
    uint32_t last = 0;
    for (;;) {
      const Phase ph = NextPhase(c_, last);
      last = ph.id;
      if (ph.quit) return;
      RunPhase(ph);
    }
  }

 private:
  void RunPhase(const Phase& ph) {
    if (!WaitEvent(
            c_,
            [&] {
              for (uint32_t s = 0; s < c_.n_subs; ++s) {
                if (c_.ready_sub[s].load() != ph.id) return false;
              }
              return true;
            },
            kConnectTimeoutNs)) {
      throw std::runtime_error("publisher: subscribers did not start the phase");
    }
    PubResult& r = c_.pubs[index_];
    r = PubResult{};
    std::vector<int64_t> drops_before(channels_.size());
    for (size_t t = 0; t < channels_.size(); ++t) drops_before[t] = channels_[t]->TransportDrops();
    const int64_t start = MonoNs() + 2'000'000 + index_ * ph.stagger_ns;
    if (ph.period_ns > 0) {
      int64_t tick = start;
      for (uint32_t k = 1; k <= ph.count; ++k) {
        if (c_.failed.load(std::memory_order_relaxed)) throw std::runtime_error("stopped");
        WaitUntil(tick, ph.busy);
        const int64_t woke = MonoNs();
        r.max_late_ns = std::max(r.max_late_ns, woke - tick);
        for (uint32_t t = 0; t < channels_.size(); ++t) PublishOne(ph, t, k, woke);
        // The next message one period after this one at the earliest, like a camera: a publisher
        // descheduled for N periods must not publish the N ticks it missed back to back. That
        // burst (1.5 MB frames at memset speed, ~10x the paced rate) overflows every depth-4
        // queue whoever reads it, and bus_bench then counted drop-oldest under an unpaced burst
        // as fast-subscriber losses of a 1 kHz stream (issue #22's `lost: 1`).
        tick = std::max(tick, woke) + ph.period_ns;
      }
      // The end marker is paced like a message: published at once it would be one message more
      // in a queue the last message may have just filled, and drop-oldest would drop a real one
      // for a subscriber that was keeping up.
      WaitUntil(tick, ph.busy);
    } else {
      WaitUntil(start, ph.busy);
      const int64_t end = start + ph.duration_ns;
      uint32_t k = 1;
      for (; k <= ph.count && MonoNs() < end; ++k) {
        if (c_.failed.load(std::memory_order_relaxed)) throw std::runtime_error("stopped");
        WaitWindow(ph, k);
        PublishOne(ph, 0, k, MonoNs());
      }
      // The end marker inside the window too, for the same reason.
      WaitWindow(ph, k);
    }
    for (size_t t = 0; t < channels_.size(); ++t) {
      const int64_t after = channels_[t]->TransportDrops();
      r.transport_drops[t] = after < 0 || drops_before[t] < 0 ? -1 : after - drops_before[t];
    }
    // Hand every byte to the kernel (UDS), then end the phase on every topic with a marker.
    FlushAll();
    for (uint32_t t = 0; t < channels_.size(); ++t) {
      try {
        std::byte* p = channels_[t]->Loan(kHeaderBytes);
        MessageHeader h;
        h.phase = ph.id;
        h.seq = kEndMarker;
        h.topic = index_ * c_.topics_per_pub + t;
        h.size = kHeaderBytes;
        h.stamp_ns = MonoNs();
        std::memcpy(p, &h, sizeof(h));
        channels_[t]->Publish();
      } catch (const std::runtime_error&) {
        // No slot for the marker: subscribers notice done_pub at their next timeout.
      }
    }
    FlushAll();
    c_.done_pub[index_].store(ph.id, std::memory_order_release);
    Signal(c_);
  }

  void FlushAll() {
    for (auto& ch : channels_) {
      if (ch->Pump(MonoNs() + 10'000'000'000, false)) {
        throw std::runtime_error("publisher: a subscriber did not read its frame within 10 s");
      }
    }
  }

  // Pacing: the publisher sleeps (in both modes; the mode is the subscribers'), moving pending UDS
  // bytes on meanwhile.
  void WaitUntil(int64_t t_ns, bool busy) {
    for (auto& ch : channels_) ch->Pump(t_ns, busy);
    SleepUntil(t_ns);
  }

  // Unpaced phases: waits until message `k` cannot overflow any fast subscriber's queue.
  void WaitWindow(const Phase& ph, uint32_t k) {
    if (ph.window == 0) return;
    auto open = [&] {
      for (uint32_t s = 0; s < c_.n_subs; ++s) {
        if (ph.slow_mask & (1u << s)) continue;
        if (c_.acked[s].load(std::memory_order_acquire) + ph.window < k) return false;
      }
      return true;
    };
    for (;;) {
      bool pending = false;
      for (auto& ch : channels_) pending |= ch->Pump(0, true);
      if (!pending && open()) return;
      if (c_.failed.load(std::memory_order_relaxed)) throw std::runtime_error("stopped");
      if (ph.busy) continue;
      if (pending) {
        for (auto& ch : channels_) ch->Pump(MonoNs() + 200'000, false);
        continue;
      }
      const uint32_t seen = c_.ack_futex.load(std::memory_order_seq_cst);
      c_.pub_waiting.store(1, std::memory_order_seq_cst);
      if (!open()) FutexWait(&c_.ack_futex, seen, 100'000'000);
      c_.pub_waiting.store(0, std::memory_order_seq_cst);
    }
  }

  // Publishes message `seq` on topic `t`; `woke` is when its pacing wait ended.
  void PublishOne(const Phase& ph, uint32_t t, uint32_t seq, int64_t woke) {
    PubResult& r = c_.pubs[index_];
    PubChannel& ch = *channels_[t];
    const uint32_t size = ph.sizes[t];
    const uint32_t topic = index_ * c_.topics_per_pub + t;
    r.attempted[t] += 1;
    const int64_t t0 = MonoNs();
    std::byte* p = nullptr;
    try {
      p = ch.Loan(size);
    } catch (const std::runtime_error&) {
      r.loan_failures += 1;  // the publisher would have been blocked: counted, message skipped
      return;
    }
    const int64_t t1 = MonoNs();
    MessageHeader h;
    h.phase = ph.id;
    h.seq = seq;
    h.topic = topic;
    h.size = size;
    h.fill = FillByte(seq, topic);
    if (ph.write_payload)
      std::memset(p + kHeaderBytes, static_cast<int>(h.fill), size - kHeaderBytes);
    h.stamp_ns = MonoNs();
    std::memcpy(p, &h, sizeof(h));
    ch.Publish();
    const int64_t t2 = MonoNs();
    r.max_fill_ns = std::max(r.max_fill_ns, h.stamp_ns - woke);
    r.max_publish_ns = std::max(r.max_publish_ns, (t1 - t0) + (t2 - h.stamp_ns));
    if (r.first_stamp_ns == 0) r.first_stamp_ns = h.stamp_ns;
    r.last_stamp_ns = h.stamp_ns;
    r.sent[t] += 1;
  }

  Control& c_;
  uint32_t index_;
  std::vector<std::unique_ptr<PubChannel>> channels_;
};

// --- Subscriber ----------------------------------------------------------------------------------

class SubscriberRole {
 public:
  SubscriberRole(Control& c, uint32_t index) : c_(c), index_(index) {
    const uint32_t topics = c.n_pubs * c.topics_per_pub;
    for (uint32_t g = 0; g < topics; ++g) {
      const TopicId id = Topic(c, g);
      switch (c.transport) {
        case Transport::kProbeless:
          channels_.push_back(MakeProbelessSub(id, c.queue_depth));
          break;
        case Transport::kUds:
          channels_.push_back(MakeUdsSub(id, c.max_bytes));
          break;
        case Transport::kIceoryx:
          channels_.push_back(MakeIceoryxSub(id, c.queue_depth));
          break;
      }
    }
  }

  void Run() {
    const int64_t deadline = MonoNs() + kConnectTimeoutNs;
    for (auto& ch : channels_) {
      while (!ch->Connected()) {
        if (MonoNs() > deadline) {
          throw std::runtime_error("subscriber: could not connect within 20 s");
        }
        if (c_.failed.load()) throw std::runtime_error("another process failed");
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
    }
    c_.connected_sub[index_].store(1);
    Signal(c_);
    uint32_t last = 0;
    for (;;) {
      const Phase ph = NextPhase(c_, last);
      last = ph.id;
      if (ph.quit) return;
      RunPhase(ph);
    }
  }

 private:
  void RunPhase(const Phase& ph) {
    SubResult& r = c_.subs[index_];
    r.n_records.store(0);
    for (uint32_t g = 0; g < kMaxTopics; ++g) {
      r.received[g] = r.checksum_errors[g] = r.stale[g] = r.reordered[g] = 0;
      r.first_recv_ns[g] = r.last_recv_ns[g] = r.max_gap_ns[g] = 0;
      r.transport_drops[g] = 0;
    }
    r.run_delay_ns.store(0);
    c_.acked[index_].store(0);
    // A busy-poll subscriber owns its core; under SCHED_FIFO it would starve the kernel's per-CPU
    // threads and hit RT throttling, so it polls at nice -20 instead.
    if (c_.realtime) SetRealtime(!ph.busy, -20);
    std::vector<int64_t> drops_before(channels_.size());
    for (size_t g = 0; g < channels_.size(); ++g) drops_before[g] = channels_[g]->TransportDrops();
    c_.ready_sub[index_].store(ph.id);
    Signal(c_);
    if (channels_.size() == 1) {
      ReceiveTopic(ph, 0);
    } else {
      std::vector<std::thread> threads;
      std::vector<std::string> errors(channels_.size());
      for (uint32_t g = 0; g < channels_.size(); ++g) {
        threads.emplace_back([&, g] {
          try {
            ReceiveTopic(ph, g);
          } catch (const std::exception& e) {
            errors[g] = e.what();
          }
        });
      }
      for (auto& t : threads) t.join();
      for (const auto& e : errors) {
        if (!e.empty()) throw std::runtime_error(e);
      }
    }
    for (size_t g = 0; g < channels_.size(); ++g) {
      const int64_t after = channels_[g]->TransportDrops();
      r.transport_drops[g] = after < 0 ? -1 : after - drops_before[g];
    }
    c_.done_sub[index_].store(ph.id, std::memory_order_release);
    Signal(c_);
  }

  void ReceiveTopic(const Phase& ph, uint32_t g) {
    SubChannel& ch = *channels_[g];
    SubResult& r = c_.subs[index_];
    const uint32_t pub = g / c_.topics_per_pub;
    const bool slow = (ph.slow_mask & (1u << index_)) != 0;
    bool draining = false;
    int64_t previous_take_ns = 0;
    uint32_t previous_seq = 0;
    const int64_t run_delay_before = ThreadRunDelayNs();
    // Every way out of the loop adds this thread's run-queue wait to the subscriber's.
    struct RunDelay {
      int64_t before;
      std::atomic<int64_t>& total;
      ~RunDelay() {
        const int64_t after = ThreadRunDelayNs();
        int64_t sum = total.load();
        int64_t next;
        do {  // -1 sticks: one thread without schedstat makes the sum unknown
          next = (before < 0 || after < 0 || sum < 0) ? -1 : sum + (after - before);
        } while (!total.compare_exchange_weak(sum, next));
      }
    } run_delay{run_delay_before, r.run_delay_ns};
    for (;;) {
      auto data =
          (ph.busy || draining) ? ch.Receive(false, 0) : ch.Receive(true, kBlockingTimeoutNs);
      if (data.empty()) {
        if (draining && !ch.InMessage()) return;
        if (!draining && c_.done_pub[pub].load(std::memory_order_acquire) == ph.id) draining = true;
        if (c_.failed.load(std::memory_order_relaxed))
          throw std::runtime_error("another process failed");
        continue;
      }
      const int64_t now = MonoNs();
      MessageHeader h;
      std::memcpy(&h, data.data(), sizeof(h));
      if (h.magic != kMessageMagic || h.phase != ph.id || h.topic != g || h.size != data.size()) {
        r.stale[g] += 1;
        ch.Release();
        continue;
      }
      if (previous_take_ns != 0) {
        r.max_gap_ns[g] = std::max(r.max_gap_ns[g], now - previous_take_ns);
      }
      previous_take_ns = now;
      if (h.seq == kEndMarker) {  // the publisher's last message of this phase on this topic
        ch.Release();
        return;
      }
      if (h.seq <= previous_seq) r.reordered[g] += 1;
      previous_seq = h.seq;
      if (ph.write_payload && !PayloadMatches(data, h.fill)) r.checksum_errors[g] += 1;
      const uint32_t n = r.n_records.fetch_add(1, std::memory_order_relaxed);
      if (n < kMaxRecords) r.records[n] = {now - h.stamp_ns, g, h.seq};
      if (r.first_recv_ns[g] == 0) r.first_recv_ns[g] = now;
      r.last_recv_ns[g] = now;
      r.received[g] += 1;
      if (slow) std::this_thread::sleep_for(std::chrono::nanoseconds(ph.slow_sleep_ns));
      ch.Release();
      c_.acked[index_].fetch_add(1, std::memory_order_seq_cst);
      if (c_.pub_waiting.load(std::memory_order_seq_cst) != 0) {
        c_.ack_futex.fetch_add(1, std::memory_order_seq_cst);
        FutexWake(&c_.ack_futex);
      }
    }
  }

  Control& c_;
  uint32_t index_;
  std::vector<std::unique_ptr<SubChannel>> channels_;
};

template <typename Role>
int RunRole(Control& c, uint32_t index, const char* role, int cpu) {
  try {
    PinToCpu(cpu);
    if (c.realtime) SetRealtime(true);
    if (c.transport == Transport::kIceoryx) InitIceoryxRuntime(RuntimeName(c, role, index));
    Role r(c, index);
    r.Run();
  } catch (const std::exception& e) {
    ReportFailure(c, std::string(role) + std::to_string(index) + ": " + e.what());
    return 2;
  }
  return 0;
}

}  // namespace

int RunPublisherRole(Control& control, uint32_t index) {
  return RunRole<PublisherRole>(control, index, "pub", control.pub_cpu[index]);
}

int RunSubscriberRole(Control& control, uint32_t index) {
  return RunRole<SubscriberRole>(control, index, "sub", control.sub_cpu[index]);
}

}  // namespace probeless::bus_bench
