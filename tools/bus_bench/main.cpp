// bus_bench: latency and throughput of the probeless bus against a Unix domain socket and iceoryx.
//
// The orchestrator (this process without --role) starts one publisher and N subscriber processes
// per transport and scenario (fork + exec of itself with --role), drives measurement phases
// through a shared control block and prints/writes the results. See --help and
// docs/benchmarks/bus.md.
#include "probeless/node/main.h"

#include <dirent.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/utsname.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <new>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "control.h"
#include "probeless/bus/bus.h"
#include "probeless/node/flags.h"
#include "probeless/parse/number.h"
#include "report.h"
#include "roudi.h"

namespace probeless::bus_bench {
namespace {

volatile sig_atomic_t g_interrupted = 0;

void OnSignal(int) { g_interrupted = 1; }

const char* TransportKey(Transport t) { return TransportName(t); }

// --- Plan ----------------------------------------------------------------------------------------

struct Plan {
  std::vector<Transport> transports;
  std::vector<uint64_t> sizes;         // 1->1 sweep
  std::vector<bool> busy_modes;        // false = blocking
  std::vector<bool> writes;            // write_payload variants
  uint32_t latency_msgs = 200;         // latency samples per 1->1 row (warm-up excluded)
  uint32_t large_msgs = 100;           // … for payloads above 2 MB (paced slower)
  uint32_t target_msgs = 1000;         // … for the target row (1,536,000 B, blocking, written)
  uint32_t multi_msgs = 150;           // … per subscriber in 1->3 rows
  uint32_t chunk_msgs = 100;           // latency runs alternate transports every this many
  uint32_t warmup = 5;                 // per chunk
  int64_t throughput_ns = 60'000'000;  // unpaced run
  std::vector<uint64_t> multi_sizes;   // 1->3 sweep (payload written)
  std::vector<bool> multi_busy_modes;
  bool slow = true;
  uint32_t slow_msgs = 200;
  bool rgbd = true;
  int64_t rgbd_ns = 3'000'000'000;
  int64_t min_period_ns = 0;  // slower pacing of every latency run (smoke: robust under load)
  bool pin = true;
  bool realtime = false;
};

constexpr uint64_t kTargetSize = 1'536'000;
constexpr uint64_t kColourBytes = 921'600;  // 640x480 RGB8
constexpr uint64_t kDepthBytes = 614'400;   // 640x480 16-bit depth
constexpr uint32_t kQueueDepth = 4;

// Pacing of latency runs: 1 kHz, slower where a copy transport could not keep up (the period must
// exceed the per-message work so that latency is not queueing).
int64_t PeriodFor(uint64_t size, uint32_t subscribers) {
  if (subscribers == 1) return size <= 2'000'000 ? 1'000'000 : 4'000'000;
  if (size <= 262'144) return 1'000'000;
  return size <= 2'000'000 ? 4'000'000 : 10'000'000;
}

// The CPUs this process may run on.
std::vector<int> AllowedCpus() {
  std::vector<int> cpus;
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) == 0) {
    for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu) {
      if (CPU_ISSET(cpu, &set)) cpus.push_back(cpu);
    }
  }
  return cpus;
}

// --- Sessions ------------------------------------------------------------------------------------

struct SessionConfig {
  Transport transport = Transport::kProbeless;
  uint32_t n_pubs = 1;
  uint32_t n_subs = 1;
  uint32_t topics_per_pub = 1;
  uint64_t max_bytes = 0;
  std::vector<int> pub_cpu;
  std::vector<int> sub_cpu;
  bool realtime = false;
};

struct SubOutcome {
  uint32_t received[kMaxTopics] = {};
  uint32_t checksum_errors = 0;
  uint32_t stale = 0;
  uint32_t reordered = 0;
  int64_t transport_drops = 0;           // -1: not counted by the transport
  int64_t topic_drops[kMaxTopics] = {};  // … per topic (-1: not counted)
  int64_t first_recv_ns = 0;             // earliest first receipt over its topics (0: none)
  int64_t last_recv_ns = 0;
  int64_t max_gap_ns = 0;    // longest interval between two takes of one topic
  int64_t run_delay_ns = 0;  // run-queue wait of its receiving threads, -1: unknown
  std::vector<LatencyRecord> records;
};

struct PhaseOutcome {
  std::vector<PubResult> pubs;
  std::vector<SubOutcome> subs;
};

// One set of role processes (publishers + subscribers) of one transport.
class Session {
 public:
  Session(const SessionConfig& config, const std::string& exe, const std::string& run_id)
      : config_(config) {
    try {
      Start(exe, run_id);
    } catch (...) {
      Shutdown();
      throw;
    }
  }

  ~Session() { Shutdown(); }

  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

  PhaseOutcome Run(Phase phase) {
    phase.id = next_phase_++;
    for (uint32_t s = 0; s < config_.n_subs; ++s) c_->acked[s].store(0);
    c_->phase = phase;
    c_->go.store(phase.id, std::memory_order_release);
    Signal(*c_);
    const int64_t expected = phase.period_ns * phase.count + phase.duration_ns +
                             phase.slow_sleep_ns * (phase.count + kQueueDepth);
    Wait(
        [&] {
          for (uint32_t i = 0; i < config_.n_pubs; ++i) {
            if (c_->done_pub[i].load(std::memory_order_acquire) != phase.id) return false;
          }
          for (uint32_t i = 0; i < config_.n_subs; ++i) {
            if (c_->done_sub[i].load(std::memory_order_acquire) != phase.id) return false;
          }
          return true;
        },
        expected + 30'000'000'000, "running a phase");
    PhaseOutcome out;
    for (uint32_t i = 0; i < config_.n_pubs; ++i) out.pubs.push_back(c_->pubs[i]);
    for (uint32_t i = 0; i < config_.n_subs; ++i) {
      const SubResult& r = c_->subs[i];
      SubOutcome s;
      const uint32_t topics = config_.n_pubs * config_.topics_per_pub;
      for (uint32_t g = 0; g < topics; ++g) {
        s.received[g] = r.received[g];
        s.checksum_errors += r.checksum_errors[g];
        s.stale += r.stale[g];
        s.reordered += r.reordered[g];
        s.topic_drops[g] = r.transport_drops[g];
        if (r.transport_drops[g] < 0) {
          s.transport_drops = -1;
        } else if (s.transport_drops >= 0) {
          s.transport_drops += r.transport_drops[g];
        }
        s.last_recv_ns = std::max(s.last_recv_ns, r.last_recv_ns[g]);
        if (r.first_recv_ns[g] != 0 &&
            (s.first_recv_ns == 0 || r.first_recv_ns[g] < s.first_recv_ns))
          s.first_recv_ns = r.first_recv_ns[g];
        s.max_gap_ns = std::max(s.max_gap_ns, r.max_gap_ns[g]);
      }
      s.run_delay_ns = r.run_delay_ns.load();
      const uint32_t n = std::min(r.n_records.load(), kMaxRecords);
      s.records.assign(r.records, r.records + n);
      out.subs.push_back(std::move(s));
    }
    return out;
  }

 private:
  void Start(const std::string& exe, const std::string& run_id) {
    const SessionConfig& config = config_;
    fd_ = memfd_create("bus_bench_control", 0);  // inherited across exec by the roles
    if (fd_ < 0) throw std::runtime_error("memfd_create failed");
    if (ftruncate(fd_, sizeof(Control)) != 0) throw std::runtime_error("ftruncate failed");
    void* p = mmap(nullptr, sizeof(Control), PROT_READ | PROT_WRITE, MAP_SHARED, fd_, 0);
    if (p == MAP_FAILED) throw std::runtime_error("mmap of the control block failed");
    c_ = new (p) Control();
    c_->transport = config.transport;
    c_->n_pubs = config.n_pubs;
    c_->n_subs = config.n_subs;
    c_->topics_per_pub = config.topics_per_pub;
    c_->max_bytes = config.max_bytes;
    c_->queue_depth = kQueueDepth;
    c_->realtime = config.realtime ? 1 : 0;
    for (uint32_t i = 0; i < config.n_pubs; ++i) {
      c_->pub_cpu[i] = i < config.pub_cpu.size() ? config.pub_cpu[i] : -1;
    }
    for (uint32_t i = 0; i < config.n_subs; ++i) {
      c_->sub_cpu[i] = i < config.sub_cpu.size() ? config.sub_cpu[i] : -1;
    }
    std::snprintf(c_->run_id, sizeof(c_->run_id), "%s", run_id.c_str());
    // Subscribers first: they create the topics; publishers then find them.
    for (uint32_t i = 0; i < config.n_subs; ++i) Spawn(exe, "sub", i);
    for (uint32_t i = 0; i < config.n_pubs; ++i) Spawn(exe, "pub", i);
    Wait(
        [&] {
          for (uint32_t i = 0; i < config.n_pubs; ++i) {
            if (!c_->connected_pub[i].load()) return false;
          }
          return true;
        },
        30'000'000'000, "connecting");
  }

  // Ends the role processes (quit phase, SIGKILL after 5 s) and releases the control block.
  void Shutdown() {
    if (c_ != nullptr) {
      c_->phase = Phase{};
      c_->phase.id = next_phase_++;
      c_->phase.quit = 1;
      c_->go.store(c_->phase.id, std::memory_order_release);
      Signal(*c_);
    }
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    for (pid_t pid : pids_) {
      int status = 0;
      while (waitpid(pid, &status, WNOHANG) == 0) {
        if (std::chrono::steady_clock::now() > deadline) {
          kill(pid, SIGKILL);
          waitpid(pid, &status, 0);
          break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
    }
    pids_.clear();
    if (c_ != nullptr) munmap(c_, sizeof(Control));
    c_ = nullptr;
    if (fd_ >= 0) close(fd_);
    fd_ = -1;
  }

  void Spawn(const std::string& exe, const char* role, uint32_t index) {
    const std::string fd = std::to_string(fd_);
    const std::string idx = std::to_string(index);
    const pid_t parent = getpid();
    const pid_t pid = fork();
    if (pid < 0) throw std::runtime_error("fork failed");
    if (pid == 0) {
      prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (getppid() != parent) _exit(1);
      execl(exe.c_str(), exe.c_str(), "--role", role, "--ctl-fd", fd.c_str(), "--index",
            idx.c_str(), static_cast<char*>(nullptr));
      _exit(127);
    }
    pids_.push_back(pid);
  }

  template <typename F>
  void Wait(F done, int64_t timeout_ns, const char* what) {
    const int64_t deadline = MonoNs() + timeout_ns;
    for (;;) {
      const uint32_t seen = c_->events.load(std::memory_order_seq_cst);
      if (done()) return;
      if (c_->failed.load()) throw std::runtime_error(c_->error);
      if (g_interrupted) {
        ReportFailure(*c_, "interrupted");  // the roles stop at once
        throw std::runtime_error("interrupted");
      }
      for (pid_t pid : pids_) {
        int status = 0;
        if (waitpid(pid, &status, WNOHANG) == pid) {
          pids_.erase(std::find(pids_.begin(), pids_.end(), pid));
          if (c_->failed.load()) throw std::runtime_error(c_->error);
          ReportFailure(*c_, "a role process exited");  // the others stop at once
          throw std::runtime_error("a role process exited unexpectedly while " + std::string(what) +
                                   " (status " + std::to_string(status) + ")");
        }
      }
      if (MonoNs() > deadline) throw std::runtime_error(std::string("timeout ") + what);
      FutexWait(&c_->events, seen, 50'000'000);
    }
  }

  SessionConfig config_;
  int fd_ = -1;
  Control* c_ = nullptr;
  std::vector<pid_t> pids_;
  uint32_t next_phase_ = 1;
};

// --- Rows ----------------------------------------------------------------------------------------

struct RowTotals {
  std::vector<int64_t> latencies;
  uint64_t lost = 0;
  int64_t counted_drops = 0;  // -1 once a phase's drops were not counted by the transport
  int64_t unexplained = 0;
  int64_t checksum_errors = 0;
  int64_t stale = 0;
  int64_t reordered = 0;
};

// Adds the fast subscribers' latencies (after warm-up) and losses of one phase, and accounts for
// the losses, per topic and summed over the fast subscribers. A miss is explained when
// - the transport counted it (probeless: the subscriber's `dropped`, its queue's drop-oldest or
//   the pool's; UDS: the publisher's drop-newest of a subscriber whose frame was still pending):
//   counted and missed must agree exactly, and
// - for drop-oldest queues (probeless, iceoryx) in a paced phase, the subscriber fell behind far
//   enough to fill its queue: a queue of depth D drops only when D messages are queued, and the
//   subscriber then takes the oldest survivor at least (D - 1) publish intervals after it was
//   stamped, so some taken message's latency is >= (D - 1) * period - max_fill (stamps are paced
//   at least period - max_fill apart, the end marker included). A transport that does not count
//   (iceoryx) is explained by this alone.
// Unpaced phases are flow-controlled (window <= D, the end marker inside it): no miss is
// explained there. Whatever load does to the scheduling, an explained miss is the documented
// keep-last policy; an unexplained one is a transport (or harness) bug.
void Accumulate(const PhaseOutcome& o, const Phase& ph, Transport transport,
                uint32_t topics_per_pub, bool latencies, RowTotals* totals,
                const std::function<bool(uint32_t)>& topic_filter) {
  for (uint32_t s = 0; s < o.subs.size(); ++s) {
    const SubOutcome& sub = o.subs[s];
    totals->checksum_errors += sub.checksum_errors;
    totals->stale += sub.stale;
    totals->reordered += sub.reordered;
  }
  const bool drop_oldest = transport != Transport::kUds;
  for (uint32_t p = 0; p < o.pubs.size(); ++p) {
    for (uint32_t t = 0; t < topics_per_pub; ++t) {
      const uint32_t g = p * topics_per_pub + t;
      if (!topic_filter(g)) continue;
      int64_t missed = 0;
      int64_t counted = 0;  // -1: not counted
      int64_t max_latency = 0;
      // Publisher-side counts are summed over every subscriber: attributable with no slow one.
      const int64_t pub_drops = ph.slow_mask != 0 ? -1 : o.pubs[p].transport_drops[t];
      bool any_counted = pub_drops >= 0;
      if (pub_drops > 0) counted += pub_drops;
      for (uint32_t s = 0; s < o.subs.size(); ++s) {
        if (ph.slow_mask & (1u << s)) continue;
        const SubOutcome& sub = o.subs[s];
        const uint32_t attempted = o.pubs[p].attempted[t];
        totals->lost += attempted > sub.received[g] ? attempted - sub.received[g] : 0;
        // A failed loan is the publisher's (loan_failures), not the transport's.
        missed += int64_t{o.pubs[p].sent[t]} - sub.received[g];
        if (sub.topic_drops[g] >= 0) {
          any_counted = true;
          counted += sub.topic_drops[g];
        }
        for (const LatencyRecord& r : sub.records) {
          if (r.topic == g) max_latency = std::max(max_latency, r.latency_ns);
        }
      }
      if (!any_counted) counted = -1;
      if (counted < 0 || totals->counted_drops < 0) {
        totals->counted_drops = -1;
      } else {
        totals->counted_drops += counted;
      }
      if (missed == 0 && counted <= 0) continue;
      int64_t unexplained = 0;
      if (ph.period_ns == 0) {
        unexplained = std::max<int64_t>(missed, counted);
      } else {
        if (counted >= 0) unexplained = std::abs(missed - counted);
        const int64_t backlog_ns =
            (int64_t{kQueueDepth} - 1) * ph.period_ns - o.pubs[p].max_fill_ns;
        if (drop_oldest && max_latency < backlog_ns) {
          unexplained = std::max<int64_t>(missed, counted);
        }
      }
      totals->unexplained += unexplained;
    }
  }
  if (!latencies) return;
  for (uint32_t s = 0; s < o.subs.size(); ++s) {
    if (ph.slow_mask & (1u << s)) continue;
    for (const LatencyRecord& r : o.subs[s].records) {
      if (r.seq > ph.warmup && topic_filter(r.topic)) totals->latencies.push_back(r.latency_ns);
    }
  }
}

// Messages per second the fast subscribers all received in an unpaced phase.
double Throughput(const PhaseOutcome& o, const Phase& ph) {
  int64_t last = 0;
  for (uint32_t s = 0; s < o.subs.size(); ++s) {
    if (!(ph.slow_mask & (1u << s))) last = std::max(last, o.subs[s].last_recv_ns);
  }
  const PubResult& pub = o.pubs[0];
  const double elapsed = static_cast<double>(last - pub.first_stamp_ns) / 1e9;
  return elapsed > 0 ? pub.sent[0] / elapsed : 0;
}

// --- Orchestrator --------------------------------------------------------------------------------

class Orchestrator {
 public:
  Orchestrator(const Plan& plan, std::string exe)
      : plan_(plan), exe_(std::move(exe)), cpus_(AllowedCpus()) {}

  void StartIceoryx(RouDi* roudi) {
    if (std::find(plan_.transports.begin(), plan_.transports.end(), Transport::kIceoryx) ==
        plan_.transports.end()) {
      return;
    }
    auto drop = [&] {
      plan_.transports.erase(
          std::find(plan_.transports.begin(), plan_.transports.end(), Transport::kIceoryx));
    };
    if (!IceoryxAvailable()) {
      std::printf(
          "iceoryx: not compiled in (find_package(iceoryx_posh) failed at configure "
          "time); no iceoryx rows\n");
      drop();
      return;
    }
    std::vector<size_t> sizes(plan_.sizes.begin(), plan_.sizes.end());
    sizes.insert(sizes.end(), plan_.multi_sizes.begin(), plan_.multi_sizes.end());
    if (plan_.slow) sizes.push_back(kTargetSize);
    if (plan_.rgbd) {
      sizes.push_back(kColourBytes);
      sizes.push_back(kDepthBytes);
    }
    std::string reason;
    const auto t0 = std::chrono::steady_clock::now();
    if (!roudi->Start(sizes, &reason)) {
      std::printf("iceoryx: iox-roudi cannot start (%s); continuing without iceoryx rows\n",
                  reason.c_str());
      drop();
      return;
    }
    std::printf(
        "iceoryx: started iox-roudi (pid %d, mempools for %zu sizes) in %.0f ms\n", roudi->pid(),
        std::set<size_t>(sizes.begin(), sizes.end()).size(),
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }

  // Runs every scenario of the plan; rows() holds what completed even if this throws.
  void RunAll() {
    PrintTableHeader();
    if (!plan_.sizes.empty()) RunFanOut(1, plan_.sizes, plan_.busy_modes, plan_.writes);
    if (!plan_.multi_sizes.empty()) {
      RunFanOut(3, plan_.multi_sizes, plan_.multi_busy_modes, {true});
    }
    if (plan_.slow) RunSlowSubscriber();
    if (plan_.rgbd) RunRgbd();
  }

  const std::vector<Row>& rows() const { return rows_; }
  int errors() const { return errors_; }

 private:
  std::string NextRunId() { return std::to_string(getpid()) + "_" + std::to_string(++sessions_); }

  int Cpu(size_t i) const { return plan_.pin && cpus_.size() >= 2 ? cpus_[i % cpus_.size()] : -1; }

  // Sessions of every transport for one scenario, created together so that the transports'
  // phases interleave in time (fair under background load).
  std::map<Transport, std::unique_ptr<Session>> OpenSessions(SessionConfig config) {
    std::map<Transport, std::unique_ptr<Session>> sessions;
    config.realtime = plan_.realtime;
    for (Transport t : plan_.transports) {
      config.transport = t;
      try {
        sessions[t] = std::make_unique<Session>(config, exe_, NextRunId());
      } catch (const std::exception& e) {
        Error(std::string(TransportKey(t)) + ": cannot start the session: " + e.what());
      }
    }
    return sessions;
  }

  void Error(const std::string& what) {
    std::printf("ERROR %s\n", what.c_str());
    std::fflush(stdout);
    ++errors_;
    if (g_interrupted) throw std::runtime_error("interrupted");
  }

  void Emit(Row row, const RowTotals& totals) {
    row.lost = totals.lost;
    row.counted_drops = totals.counted_drops;
    row.unexplained = totals.unexplained;
    row.checksum_errors = totals.checksum_errors;
    row.stale = totals.stale;
    row.reordered = totals.reordered;
    SetLatencies(row, totals.latencies);
    if (row.checksum_errors != 0 || row.stale != 0 || row.reordered != 0) ++errors_;
    PrintRow(row);
    rows_.push_back(row);
  }

  // 1->N rows: per (mode, payload writing, size) a paced latency run, split into chunks that
  // alternate between the transports (so that background noise hits them alike), then an unpaced
  // throughput run per transport.
  void RunFanOut(uint32_t n_subs, const std::vector<uint64_t>& sizes,
                 const std::vector<bool>& busy_modes, const std::vector<bool>& writes) {
    SessionConfig config;
    config.n_subs = n_subs;
    config.max_bytes = *std::max_element(sizes.begin(), sizes.end());
    // The publisher's core stays free of subscribers (no preemption inside Publish); several
    // subscribers share the other core.
    config.pub_cpu = {Cpu(0)};
    config.sub_cpu = std::vector<int>(n_subs, Cpu(1));
    auto sessions = OpenSessions(config);
    for (bool busy : busy_modes) {
      for (bool write : writes) {
        for (uint64_t size : sizes) {
          const bool target = n_subs == 1 && size == kTargetSize && !busy && write;
          const uint32_t msgs = n_subs > 1         ? plan_.multi_msgs
                                : target           ? plan_.target_msgs
                                : size > 2'000'000 ? plan_.large_msgs
                                                   : plan_.latency_msgs;
          const uint32_t chunks = std::max<uint32_t>(1, msgs / plan_.chunk_msgs);
          Phase lat;
          lat.busy = busy;
          lat.write_payload = write;
          lat.sizes[0] = static_cast<uint32_t>(size);
          lat.warmup = plan_.warmup;
          lat.count = plan_.warmup + msgs / chunks;
          lat.period_ns = std::max(PeriodFor(size, n_subs), plan_.min_period_ns);
          Phase tput = lat;
          tput.period_ns = 0;
          tput.count = 10'000'000;
          tput.duration_ns = plan_.throughput_ns;
          tput.window = kQueueDepth;

          std::map<Transport, Row> rows;
          std::map<Transport, RowTotals> totals;
          for (auto& [transport, session] : sessions) {
            Row& row = rows[transport];
            row.transport = TransportKey(transport);
            row.scenario = n_subs == 1 ? "1to1" : "1to3";
            row.mode = busy ? "busy" : "blocking";
            row.size = size;
            row.subscribers = n_subs;
            row.write_payload = write;
            row.rate_hz = 1e9 / static_cast<double>(lat.period_ns);
            row.max_publish_us = 0;
          }
          auto run = [&](Transport transport, const Phase& ph) -> std::optional<PhaseOutcome> {
            auto& session = sessions[transport];
            if (!session) return std::nullopt;
            try {
              return session->Run(ph);
            } catch (const std::exception& e) {
              Error(std::string(TransportKey(transport)) + " " + rows[transport].scenario + " " +
                    std::to_string(size) + " B: " + e.what());
              session.reset();
              return std::nullopt;
            }
          };
          for (uint32_t chunk = 0; chunk < chunks; ++chunk) {
            for (size_t k = 0; k < plan_.transports.size(); ++k) {
              // Rotate the order so no transport always runs first.
              const Transport t = plan_.transports[(k + chunk) % plan_.transports.size()];
              const auto o = run(t, lat);
              if (!o) continue;
              Accumulate(*o, lat, t, 1, true, &totals[t], [](uint32_t) { return true; });
              rows[t].max_publish_us = std::max(
                  rows[t].max_publish_us, static_cast<double>(o->pubs[0].max_publish_ns) / 1e3);
              rows[t].loan_failures += o->pubs[0].loan_failures;
            }
          }
          for (Transport t : plan_.transports) {
            const auto o = run(t, tput);
            if (!o) continue;
            Accumulate(*o, tput, t, 1, false, &totals[t], [](uint32_t) { return true; });
            rows[t].msgs_per_s = Throughput(*o, tput);
            rows[t].mb_per_s = rows[t].msgs_per_s * static_cast<double>(size) / 1e6;
            rows[t].loan_failures += o->pubs[0].loan_failures;
            Emit(rows[t], totals[t]);
          }
        }
      }
    }
  }

  void RunSlowSubscriber() {
    SessionConfig config;
    config.n_subs = 3;
    config.max_bytes = kTargetSize;
    config.pub_cpu = {Cpu(0)};
    config.sub_cpu = {Cpu(1), Cpu(1), Cpu(1)};
    auto sessions = OpenSessions(config);
    for (auto& [transport, session] : sessions) {
      if (!session) continue;
      Phase ph;
      ph.write_payload = 1;
      ph.sizes[0] = kTargetSize;
      ph.warmup = plan_.warmup;
      ph.count = plan_.warmup + plan_.slow_msgs;
      ph.period_ns = PeriodFor(kTargetSize, 1);
      ph.slow_mask = 1u << 2;
      ph.slow_sleep_ns = 10'000'000;  // the slow one takes 10 ms per message, holding it
      Row row;
      row.transport = TransportKey(transport);
      row.scenario = "slow_subscriber";
      row.mode = "blocking";
      row.size = kTargetSize;
      row.subscribers = 3;
      row.write_payload = true;
      row.rate_hz = 1e9 / static_cast<double>(ph.period_ns);
      try {
        RowTotals totals;
        const PhaseOutcome o = session->Run(ph);
        Accumulate(o, ph, transport, 1, true, &totals, [](uint32_t) { return true; });
        const PubResult& pub = o.pubs[0];
        const SubOutcome& slow = o.subs[2];
        row.slow_received = slow.received[0];
        row.slow_lost = pub.attempted[0] - slow.received[0];
        row.slow_transport_drops = slow.transport_drops;
        // What the fast subscribers' misses were: drops of their own full queues (the bus's
        // policy, counted by it) while they took nothing for a while (the longest such interval,
        // the start counted from the first publish) and waited on a run queue (other load).
        row.fast_transport_drops = 0;
        row.fast_max_gap_us = 0;
        row.fast_run_delay_us = 0;
        row.fast_unexplained = 0;
        // A subscriber that took nothing for (depth - 1) periods let its queue fill.
        const int64_t stall_ns = (kQueueDepth - 1) * ph.period_ns;
        for (uint32_t s = 0; s < o.subs.size(); ++s) {
          if (ph.slow_mask & (1u << s)) continue;
          const SubOutcome& fast = o.subs[s];
          if (fast.transport_drops < 0 || row.fast_transport_drops < 0) {
            row.fast_transport_drops = -1;
          } else {
            row.fast_transport_drops += fast.transport_drops;
          }
          int64_t gap = fast.max_gap_ns;
          if (fast.first_recv_ns != 0) gap = std::max(gap, fast.first_recv_ns - pub.first_stamp_ns);
          row.fast_max_gap_us = std::max(row.fast_max_gap_us, static_cast<double>(gap) / 1e3);
          if (fast.run_delay_ns < 0 || row.fast_run_delay_us < 0) {
            row.fast_run_delay_us = -1;
          } else {
            row.fast_run_delay_us =
                std::max(row.fast_run_delay_us, static_cast<double>(fast.run_delay_ns) / 1e3);
          }
          const int64_t missed = int64_t{pub.attempted[0]} - fast.received[0];
          // Always checked: a transport that counts more drops than the subscriber missed, or a
          // subscriber that got more than was sent, means this accounting is wrong, not the bus.
          if (missed < 0 || fast.transport_drops > missed) {
            throw std::runtime_error("accounting: fast subscriber " + std::to_string(s) + " got " +
                                     std::to_string(fast.received[0]) + " of " +
                                     std::to_string(pub.attempted[0]) + " with " +
                                     std::to_string(fast.transport_drops) + " drops counted");
          }
          const bool own_queue = fast.transport_drops == missed;
          const bool stalled =
              gap >= stall_ns && (fast.run_delay_ns < 0 || fast.run_delay_ns >= stall_ns);
          if (missed > 0 && !(own_queue && stalled)) row.fast_unexplained += missed;
        }
        row.max_publish_us = static_cast<double>(pub.max_publish_ns) / 1e3;
        row.loan_failures = pub.loan_failures;
        const double span = static_cast<double>(pub.last_stamp_ns - pub.first_stamp_ns) / 1e9;
        row.msgs_per_s = span > 0 ? (pub.sent[0] - 1) / span : 0;
        row.mb_per_s = row.msgs_per_s * static_cast<double>(kTargetSize) / 1e6;
        Emit(row, totals);
      } catch (const std::exception& e) {
        Error(row.transport + " slow_subscriber: " + e.what());
      }
    }
  }

  void RunRgbd() {
    SessionConfig config;
    config.n_pubs = 4;
    config.n_subs = 3;
    config.topics_per_pub = 2;
    config.max_bytes = kColourBytes;
    auto sessions = OpenSessions(config);
    for (auto& [transport, session] : sessions) {
      if (!session) continue;
      Phase ph;
      ph.write_payload = 1;
      ph.sizes[0] = kColourBytes;
      ph.sizes[1] = kDepthBytes;
      ph.period_ns = 33'333'333;
      ph.count = static_cast<uint32_t>(plan_.rgbd_ns / ph.period_ns);
      ph.stagger_ns = ph.period_ns / 4;  // unsynchronised cameras
      ph.warmup = 0;
      try {
        const PhaseOutcome o = session->Run(ph);
        for (uint32_t kind = 0; kind < 2; ++kind) {
          RowTotals totals;
          auto of_kind = [kind](uint32_t topic) { return topic % 2 == kind; };
          Accumulate(o, ph, transport, 2, true, &totals, of_kind);
          Row row;
          row.transport = TransportKey(transport);
          row.scenario = "4x_rgbd_30fps";
          row.mode = "blocking";
          row.size = kind == 0 ? kColourBytes : kDepthBytes;
          row.subscribers = 3;
          row.write_payload = true;
          row.rate_hz = 30;
          uint64_t delivered = 0;
          for (const SubOutcome& s : o.subs) {
            for (uint32_t g = kind; g < kMaxTopics; g += 2) delivered += s.received[g];
          }
          row.msgs_per_s = static_cast<double>(delivered) / (plan_.rgbd_ns / 1e9);
          row.mb_per_s = row.msgs_per_s * static_cast<double>(row.size) / 1e6;
          int64_t max_publish = 0;
          for (const PubResult& p : o.pubs) {
            max_publish = std::max(max_publish, p.max_publish_ns);
            row.loan_failures += p.loan_failures;
          }
          row.max_publish_us = static_cast<double>(max_publish) / 1e3;
          Emit(row, totals);
        }
      } catch (const std::exception& e) {
        Error(std::string(TransportKey(transport)) + " 4x_rgbd_30fps: " + e.what());
      }
    }
  }

  Plan plan_;
  std::string exe_;
  std::vector<int> cpus_;
  std::vector<Row> rows_;
  int sessions_ = 0;
  int errors_ = 0;
};

// --- Wake-up floor ------------------------------------------------------------------------------

// The hand-over cost of this machine without any transport: one process stamps CLOCK_MONOTONIC
// and bumps a shared word at 1 kHz, another (pinned like the 1->1 subscriber) waits for it on a
// futex (blocking) or spins on it (busy). No blocking transport can beat the futex figure.
WakeFloor MeasureWakeFloor(int pub_cpu, int sub_cpu, uint32_t samples) {
  struct Shared {
    std::atomic<uint32_t> word{0};
    std::atomic<int64_t> stamp{0};
    std::atomic<uint32_t> n{0};
    int64_t latency_ns[4096];
  };
  samples = std::min<uint32_t>(samples, 4096);
  WakeFloor floor;
  void* p =
      mmap(nullptr, sizeof(Shared), PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) return floor;
  cpu_set_t saved;
  sched_getaffinity(0, sizeof(saved), &saved);
  for (bool spin : {false, true}) {
    Shared* shm = new (p) Shared();
    const pid_t child = fork();
    if (child < 0) break;
    if (child == 0) {
      PinToCpu(sub_cpu);
      uint32_t seen = 0;
      for (;;) {
        uint32_t w = 0;
        while ((w = shm->word.load(std::memory_order_acquire)) == seen) {
          if (!spin) FutexWait(&shm->word, seen, 100'000'000);
        }
        const int64_t now = MonoNs();
        if (w == UINT32_MAX) _exit(0);
        const uint32_t i = shm->n.load();
        if (i < 4096) shm->latency_ns[i] = now - shm->stamp.load();
        shm->n.store(i + 1);
        seen = w;
      }
    }
    PinToCpu(pub_cpu);
    const int64_t start = MonoNs() + 5'000'000;
    for (uint32_t i = 1; i <= samples + 5; ++i) {
      const int64_t tick = start + int64_t{i} * 1'000'000;
      const timespec ts{tick / 1'000'000'000, tick % 1'000'000'000};
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
      }
      shm->stamp.store(MonoNs());
      shm->word.store(i, std::memory_order_release);
      if (!spin) FutexWake(&shm->word);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
    shm->word.store(UINT32_MAX);
    FutexWake(&shm->word);
    waitpid(child, nullptr, 0);
    sched_setaffinity(0, sizeof(saved), &saved);
    const uint32_t n = std::min<uint32_t>(shm->n.load(), 4096);
    std::vector<int64_t> latencies(shm->latency_ns + std::min<uint32_t>(5, n), shm->latency_ns + n);
    std::sort(latencies.begin(), latencies.end());
    (spin ? floor.spin_p50_us : floor.futex_p50_us) = Percentile(latencies, 0.5) / 1e3;
    (spin ? floor.spin_p99_us : floor.futex_p99_us) = Percentile(latencies, 0.99) / 1e3;
  }
  munmap(p, sizeof(Shared));
  return floor;
}

// --- Environment ---------------------------------------------------------------------------------

std::string CpuModel() {
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  }
  return "unknown";
}

std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a + " " + b + " " + c;
}

// Names in /dev/shm starting with `prefix`.
std::vector<std::string> ShmEntries(const std::string& prefix) {
  std::vector<std::string> names;
  if (DIR* dir = opendir("/dev/shm")) {
    while (dirent* ent = readdir(dir)) {
      if (std::string(ent->d_name).rfind(prefix, 0) == 0) names.push_back(ent->d_name);
    }
    closedir(dir);
  }
  return names;
}

constexpr char kDescription[] =
    "One-way latency (p50/p90/p99/p99.9/max) and throughput of the probeless bus, a Unix\n"
    "domain socket and iceoryx (a private iox-roudi is started) between processes. By default:\n"
    "1->1 blocking+busy, payload written or not, 1 KB..4 MB; 1->3; a slow subscriber; 4 RGB-D\n"
    "streams at 30 fps to 3 subscribers for 3 s (< 45 s).";

std::vector<std::string> Split(const std::string& s) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= s.size()) {
    const size_t comma = s.find(',', start);
    const size_t end = comma == std::string::npos ? s.size() : comma;
    if (end > start) out.push_back(s.substr(start, end - start));
    start = end + 1;
  }
  return out;
}

int RunRole(const std::string& role, int fd, uint32_t index) {
  void* p = mmap(nullptr, sizeof(Control), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  if (p == MAP_FAILED) {
    std::fprintf(stderr, "bus_bench: cannot map the control block (fd %d)\n", fd);
    return 2;
  }
  close(fd);
  Control& control = *static_cast<Control*>(p);
  if (role == "pub" && index < control.n_pubs) return RunPublisherRole(control, index);
  if (role == "sub" && index < control.n_subs) return RunSubscriberRole(control, index);
  std::fprintf(stderr, "bus_bench: bad role '%s' index %u\n", role.c_str(), index);
  return 2;
}

int Main(int argc, char** argv) {
  std::string json_path, role, transports_arg, sizes_arg;
  int ctl_fd = -1;
  uint32_t index = 0;
  bool full = false, smoke = false, pin = true, realtime = false;
  node::FlagParser flags("bus_bench", kDescription);
  flags.Add("--json", &json_path, "FILE", "also write the rows as a JSON array to FILE");
  flags.Add("--full", &full, "11 sizes, 2000-5000 samples per row, more 1->3 sizes (~8 minutes)");
  flags.Add("--smoke", &smoke, "a < 5 s subset (ctest)");
  flags.Add("--transports", &transports_arg, "T,...",
            "transports to run: probeless,uds,iceoryx (default all three)");
  flags.Add("--sizes", &sizes_arg, "B,...", "payload sizes in bytes of the 1->1 sweep");
  flags.AddSwitch(
      "--no-pin", [&] { pin = false; }, "do not pin the publisher/subscriber to cores");
  flags.Add("--rt", &realtime,
            "run publishers and blocking subscribers SCHED_FIFO (busy-poll subscribers nice "
            "-20): figures of the transports, not of the competing load");
  flags.Add("--role", &role, "pub|sub", "internal: a child process of the orchestrator");
  flags.Add("--ctl-fd", &ctl_fd, "FD", "internal: the control block's descriptor", 0);
  flags.Add("--index", &index, "I", "internal: the child's index");
  if (!flags.Parse(argc, argv)) return 0;
  if (!role.empty()) return RunRole(role, ctl_fd, index);
  if (full && smoke) throw node::UsageError("--full and --smoke exclude each other");

  Plan plan;
  plan.pin = pin;
  if (realtime) {
    // Probe once here; the roles then set it for themselves.
    if (SetRealtime(true)) {
      SetRealtime(false, 0);
      plan.realtime = true;
    } else {
      std::printf("--rt: SCHED_FIFO not permitted (%s); running without it\n",
                  std::strerror(errno));
    }
  }
  plan.transports = {Transport::kProbeless, Transport::kUds, Transport::kIceoryx};
  plan.sizes = {1024, kDepthBytes, kColourBytes, kTargetSize, 4'194'304};
  plan.busy_modes = {false, true};
  plan.writes = {false, true};
  plan.multi_sizes = {1024, kTargetSize};
  plan.multi_busy_modes = {false};
  if (full) {
    plan.sizes = {1024,         4096,      16'384,      65'536,    262'144,  kDepthBytes,
                  kColourBytes, 1'048'576, kTargetSize, 2'097'152, 4'194'304};
    plan.latency_msgs = 2000;
    plan.large_msgs = 1000;
    plan.target_msgs = 5000;
    plan.multi_msgs = 500;
    plan.warmup = 20;
    plan.throughput_ns = 300'000'000;
    // 1->3 stays blocking: three busy pollers on this 2-core machine would only measure the
    // scheduler sharing one core between them.
    plan.multi_sizes = {1024, 65'536, kDepthBytes, kColourBytes, kTargetSize, 4'194'304};
    plan.slow_msgs = 1000;
  }
  if (smoke) {
    plan.sizes = {1024, kTargetSize};
    plan.busy_modes = {false};
    plan.writes = {true};
    plan.latency_msgs = 50;
    plan.target_msgs = 100;
    plan.throughput_ns = 50'000'000;
    plan.min_period_ns = 4'000'000;  // 250 Hz: a loaded machine must not make ctest flaky
    plan.multi_sizes = {};
    // The slow-subscriber scenario stays (0.1 s): ctest checks that a fast subscriber loses
    // nothing but what its own full queue dropped (check_smoke.cmake).
    plan.slow_msgs = 50;
    plan.rgbd = false;
  }
  if (!transports_arg.empty()) {
    plan.transports.clear();
    for (const std::string& t : Split(transports_arg)) {
      if (t == "probeless") {
        plan.transports.push_back(Transport::kProbeless);
      } else if (t == "uds") {
        plan.transports.push_back(Transport::kUds);
      } else if (t == "iceoryx") {
        plan.transports.push_back(Transport::kIceoryx);
      } else {
        throw node::UsageError("unknown transport '" + t +
                               "' (expected probeless, uds or iceoryx)");
      }
    }
  }
  if (!sizes_arg.empty()) {
    plan.sizes.clear();
    for (const std::string& s : Split(sizes_arg)) {
      const uint64_t size = parse::ParseInteger<uint64_t>("--sizes item", s, uint64_t{kHeaderBytes},
                                                          uint64_t{64u << 20});
      plan.sizes.push_back(size);
    }
  }

  // Every probeless segment of this run lives in its own domain.
  const std::string domain = "bench_" + std::to_string(getpid());
  setenv("PROBELESS_DOMAIN", domain.c_str(), 1);
  struct sigaction sa {};
  sa.sa_handler = OnSignal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  sigaction(SIGHUP, &sa, nullptr);
  sigaction(SIGPIPE, &sa, nullptr);  // e.g. `bus_bench | head`: stop, but clean up first

  char exe[4096];
  const ssize_t n = readlink("/proc/self/exe", exe, sizeof(exe) - 1);
  if (n <= 0) throw std::runtime_error("cannot resolve /proc/self/exe");
  exe[n] = '\0';

  utsname uts{};
  uname(&uts);
  std::printf("bus_bench: %s, %ld online cores, Linux %s, load average %s, domain %s%s%s\n",
              CpuModel().c_str(), sysconf(_SC_NPROCESSORS_ONLN), uts.release, LoadAverage().c_str(),
              domain.c_str(), pin ? "" : ", unpinned", plan.realtime ? ", SCHED_FIFO roles" : "");
  const auto start = std::chrono::steady_clock::now();
  const std::vector<int> cpus = AllowedCpus();
  const bool pinned = pin && cpus.size() >= 2;
  const int pub_cpu = pinned ? cpus[0] : -1;
  const int sub_cpu = pinned ? cpus[1] : -1;
  const WakeFloor floor = MeasureWakeFloor(pub_cpu, sub_cpu, smoke ? 100 : 300);
  std::printf(
      "wake-up floor (no transport: bare shared futex / spin between 2 %s processes, "
      "1 kHz): futex p50 %.1f us p99 %.1f us, spin p50 %.1f us p99 %.1f us\n",
      pinned ? "pinned" : "unpinned", floor.futex_p50_us, floor.futex_p99_us, floor.spin_p50_us,
      floor.spin_p99_us);

  int status = 0;
  std::vector<Row> rows;
  {
    RouDi roudi;
    Orchestrator orchestrator(plan, exe);
    orchestrator.StartIceoryx(&roudi);
    try {
      orchestrator.RunAll();
    } catch (const std::exception& e) {
      std::printf("ERROR %s\n", e.what());
      status = 1;
    }
    rows = orchestrator.rows();
    if (orchestrator.errors() != 0) status = 1;
    roudi.Stop();
  }
  // iceoryx clients leave /tmp/<runtime name>{,.lock} behind only if killed; ours are
  // bus_bench_<pid>_*.
  if (DIR* dir = opendir("/tmp")) {
    const std::string prefix = "bus_bench_" + std::to_string(getpid()) + "_";
    while (dirent* ent = readdir(dir)) {
      if (std::string(ent->d_name).rfind(prefix, 0) == 0) {
        unlink(("/tmp/" + std::string(ent->d_name)).c_str());
      }
    }
    closedir(dir);
  }
  const int misses = PrintTargetChecks(rows, floor);

  // Nothing may be left in /dev/shm: probeless segments of this domain, RouDi's segments.
  bus::CleanDeadSegments(domain);
  const auto leftovers = ShmEntries("probeless." + std::to_string(getuid()) + "." + domain + ".");
  for (const auto& name : leftovers) std::printf("ERROR left in /dev/shm: %s\n", name.c_str());
  if (!leftovers.empty()) status = 1;
  if (!ShmEntries("iceoryx_mgmt").empty()) {
    std::printf("WARNING /dev/shm/iceoryx_mgmt exists (another RouDi running?)\n");
  }

  if (!json_path.empty()) {
    std::string error;
    if (!WriteJson(json_path, rows, &error)) {
      std::printf("ERROR %s\n", error.c_str());
      status = 1;
    } else {
      std::printf("wrote %zu rows to %s\n", rows.size(), json_path.c_str());
    }
  }
  std::printf("bus_bench: %zu rows, %d target misses, %.1f s\n", rows.size(), misses,
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  if (g_interrupted) status = 130;
  return status;
}

}  // namespace

const char* TransportName(Transport transport) {
  switch (transport) {
    case Transport::kProbeless:
      return "probeless";
    case Transport::kUds:
      return "uds";
    case Transport::kIceoryx:
      return "iceoryx";
  }
  return "?";
}

}  // namespace probeless::bus_bench

int main(int argc, char** argv) {
  return probeless::node::RunMain("bus_bench",
                                  [&] { return probeless::bus_bench::Main(argc, argv); });
}
