// bus_bench: result rows, the readable table, the JSON file and the target checks.
#include "report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <optional>
#include <sstream>

namespace probeless::bus_bench {
namespace {

constexpr double kTargetP50Us = 20;
constexpr double kTargetP99Us = 100;
constexpr double kMaxRatioToIceoryx = 1.5;
constexpr double kMinRatioUdsOverProbeless = 10;
constexpr uint64_t kTargetSize = 1'536'000;

std::string Fixed(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.*f", digits, v);
  return buf;
}

const Row* FindTargetRow(const std::vector<Row>& rows, const std::string& transport,
                         const char* mode = "blocking") {
  for (const Row& r : rows) {
    if (r.transport == transport && r.scenario == "1to1" && r.mode == mode &&
        r.size == kTargetSize && r.write_payload) {
      return &r;
    }
  }
  return nullptr;
}

// A percentile of probeless and of the transport it is compared with.
struct Pair {
  const char* name;
  double mine;
  double theirs;
};

void Check(int* misses, bool pass, const std::string& text) {
  std::printf("  %-4s  %s\n", pass ? "PASS" : "MISS", text.c_str());
  if (!pass) ++*misses;
}

}  // namespace

double Percentile(const std::vector<int64_t>& sorted, double q) {
  if (sorted.empty()) return 0;
  const double rank = std::ceil(q * static_cast<double>(sorted.size()));
  const size_t index = static_cast<size_t>(std::clamp(rank, 1.0, double(sorted.size()))) - 1;
  return static_cast<double>(sorted[index]);
}

void SetLatencies(Row& row, std::vector<int64_t> latencies_ns) {
  std::sort(latencies_ns.begin(), latencies_ns.end());
  row.samples = latencies_ns.size();
  row.p50_us = Percentile(latencies_ns, 0.50) / 1e3;
  row.p90_us = Percentile(latencies_ns, 0.90) / 1e3;
  row.p99_us = Percentile(latencies_ns, 0.99) / 1e3;
  row.p999_us = Percentile(latencies_ns, 0.999) / 1e3;
  row.max_us = latencies_ns.empty() ? 0 : static_cast<double>(latencies_ns.back()) / 1e3;
}

void PrintTableHeader() {
  std::printf("%-9s %-15s %4s %-8s %5s %9s %5s %9s %9s %9s %9s %9s %10s %8s %6s\n", "transport",
              "scenario", "subs", "mode", "write", "size_B", "n", "p50_us", "p90_us", "p99_us",
              "p99.9_us", "max_us", "msgs_per_s", "MB_per_s", "lost");
}

void PrintRow(const Row& r) {
  std::printf(
      "%-9s %-15s %4u %-8s %5s %9llu %5llu %9.1f %9.1f %9.1f %9.1f %9.1f %10.0f %8.0f %6llu",
      r.transport.c_str(), r.scenario.c_str(), r.subscribers, r.mode.c_str(),
      r.write_payload ? "yes" : "no", static_cast<unsigned long long>(r.size),
      static_cast<unsigned long long>(r.samples), r.p50_us, r.p90_us, r.p99_us, r.p999_us, r.max_us,
      r.msgs_per_s, r.mb_per_s, static_cast<unsigned long long>(r.lost));
  if (r.slow_received >= 0) {
    std::printf("  slow: got %lld missed %lld", static_cast<long long>(r.slow_received),
                static_cast<long long>(r.slow_lost));
    if (r.slow_transport_drops >= 0) {
      std::printf(" (bus counted %lld)", static_cast<long long>(r.slow_transport_drops));
    }
    std::printf(", max publish %.1f us, loan failures %lld", r.max_publish_us,
                static_cast<long long>(r.loan_failures));
    if (r.lost != 0) {
      std::printf(
          "; fast: %lld queue drops, took nothing for up to %.1f ms, run-queue wait %.1f ms",
          static_cast<long long>(r.fast_transport_drops), r.fast_max_gap_us / 1e3,
          r.fast_run_delay_us / 1e3);
    }
  }
  if (r.lost != 0 || r.unexplained != 0) {
    std::printf("  (");
    if (r.counted_drops >= 0) {
      std::printf("transport counted %lld, ", static_cast<long long>(r.counted_drops));
    }
    std::printf("unexplained %lld)", static_cast<long long>(r.unexplained));
  }
  if (r.checksum_errors != 0 || r.stale != 0 || r.reordered != 0) {
    std::printf("  CHECKSUM ERRORS %lld, STALE %lld, REORDERED %lld",
                static_cast<long long>(r.checksum_errors), static_cast<long long>(r.stale),
                static_cast<long long>(r.reordered));
  }
  std::printf("\n");
  std::fflush(stdout);
}

bool WriteJson(const std::string& path, const std::vector<Row>& rows, std::string* error) {
  std::ostringstream out;
  out << "[\n";
  for (size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    out << "  {\"transport\": \"" << r.transport << "\", \"size\": " << r.size << ", \"mode\": \""
        << r.mode << "\", \"subscribers\": " << r.subscribers
        << ", \"p50_us\": " << Fixed(r.p50_us, 2) << ", \"p90_us\": " << Fixed(r.p90_us, 2)
        << ", \"p99_us\": " << Fixed(r.p99_us, 2) << ", \"max_us\": " << Fixed(r.max_us, 2)
        << ", \"msgs_per_s\": " << Fixed(r.msgs_per_s, 1) << ", \"lost\": " << r.lost
        << ", \"p999_us\": " << Fixed(r.p999_us, 2) << ", \"scenario\": \"" << r.scenario
        << "\", \"write_payload\": " << (r.write_payload ? "true" : "false")
        << ", \"samples\": " << r.samples << ", \"rate_hz\": " << Fixed(r.rate_hz, 1)
        << ", \"mb_per_s\": " << Fixed(r.mb_per_s, 1)
        << ", \"checksum_errors\": " << r.checksum_errors
        << ", \"loan_failures\": " << r.loan_failures << ", \"counted_drops\": " << r.counted_drops
        << ", \"unexplained\": " << r.unexplained << ", \"reordered\": " << r.reordered
        << ", \"stale\": " << r.stale;
    if (r.max_publish_us >= 0) out << ", \"max_publish_us\": " << Fixed(r.max_publish_us, 2);
    if (r.slow_received >= 0) {
      out << ", \"slow_received\": " << r.slow_received << ", \"slow_lost\": " << r.slow_lost;
      if (r.slow_transport_drops >= 0) {
        out << ", \"slow_transport_drops\": " << r.slow_transport_drops;
      }
      if (r.fast_transport_drops >= 0) {
        out << ", \"fast_transport_drops\": " << r.fast_transport_drops;
      }
      out << ", \"fast_max_gap_us\": " << Fixed(r.fast_max_gap_us, 1)
          << ", \"fast_unexplained\": " << r.fast_unexplained;
      if (r.fast_run_delay_us >= 0) {
        out << ", \"fast_run_delay_us\": " << Fixed(r.fast_run_delay_us, 1);
      }
    }
    out << "}" << (i + 1 < rows.size() ? "," : "") << "\n";
  }
  out << "]\n";
  std::ofstream file(path);
  file << out.str();
  file.close();
  if (!file) {
    *error = "cannot write " + path;
    return false;
  }
  return true;
}

void Info(const std::string& text) { std::printf("  INFO  %s\n", text.c_str()); }

int PrintTargetChecks(const std::vector<Row>& rows, const WakeFloor& floor) {
  int misses = 0;
  std::printf("\nTarget checks (1,536,000-byte frames, 1->1, blocking Take, payload written):\n");
  const Row* p = FindTargetRow(rows, "probeless");
  const Row* ice = FindTargetRow(rows, "iceoryx");
  const Row* uds = FindTargetRow(rows, "uds");
  if (p == nullptr) {
    std::printf("  SKIP  no probeless row for 1,536,000 B blocking (run without --sizes?)\n");
  } else {
    Check(&misses, p->p50_us <= kTargetP50Us,
          "probeless p50 " + Fixed(p->p50_us, 1) + " us <= " + Fixed(kTargetP50Us, 0) + " us");
    Check(&misses, p->p99_us <= kTargetP99Us,
          "probeless p99 " + Fixed(p->p99_us, 1) + " us <= " + Fixed(kTargetP99Us, 0) + " us");
    if (ice == nullptr) {
      std::printf("  SKIP  latency within 1.5x of iceoryx: no iceoryx rows\n");
    } else {
      for (const Pair& x :
           {Pair{"p50", p->p50_us, ice->p50_us}, Pair{"p99", p->p99_us, ice->p99_us}}) {
        const auto& [name, mine, theirs] = x;
        Check(&misses, mine <= kMaxRatioToIceoryx * theirs,
              std::string(name) + " vs iceoryx: " + Fixed(mine, 1) + " / " + Fixed(theirs, 1) +
                  " us = " + Fixed(mine / theirs, 2) +
                  "x (target <= " + Fixed(kMaxRatioToIceoryx, 1) + "x)");
      }
    }
    if (uds == nullptr) {
      std::printf("  SKIP  >= 10x better than UDS: no uds rows\n");
    } else {
      for (const Pair& x :
           {Pair{"p50", p->p50_us, uds->p50_us}, Pair{"p99", p->p99_us, uds->p99_us}}) {
        const auto& [name, mine, theirs] = x;
        Check(&misses, theirs >= kMinRatioUdsOverProbeless * mine,
              std::string(name) + " uds / probeless: " + Fixed(theirs, 1) + " / " + Fixed(mine, 1) +
                  " us = " + Fixed(theirs / mine, 1) +
                  "x (target >= " + Fixed(kMinRatioUdsOverProbeless, 0) + "x)");
      }
    }
  }
  // Context: what no blocking transport can beat here, and the same comparison in busy-poll mode.
  Info("wake-up floor of this machine (bare futex, no transport): p50 " +
       Fixed(floor.futex_p50_us, 1) + " us, p99 " + Fixed(floor.futex_p99_us, 1) +
       " us; spinning waiter: p50 " + Fixed(floor.spin_p50_us, 1) + " us");
  if (const Row* busy = FindTargetRow(rows, "probeless", "busy")) {
    std::string text = "busy-poll (TryTake loop), same frames: probeless p50 " +
                       Fixed(busy->p50_us, 1) + " us, p99 " + Fixed(busy->p99_us, 1) + " us";
    if (const Row* b = FindTargetRow(rows, "iceoryx", "busy")) {
      text += "; iceoryx p50 " + Fixed(b->p50_us, 1) + " us (" +
              Fixed(busy->p50_us / b->p50_us, 2) + "x)";
    }
    if (const Row* b = FindTargetRow(rows, "uds", "busy")) {
      text += "; uds p50 " + Fixed(b->p50_us, 1) + " us (" + Fixed(b->p50_us / busy->p50_us, 0) +
              "x slower)";
    }
    Info(text);
  }
  // Delivery checks of every scenario that ran.
  uint64_t lost_1to1 = 0;
  int64_t counted_1to1 = 0, unexplained_1to1 = 0;
  int n_1to1 = 0;
  for (const Row& r : rows) {
    if (r.scenario == "1to1" && r.transport == "probeless") {
      lost_1to1 += r.lost;
      counted_1to1 += r.counted_drops;
      unexplained_1to1 += r.unexplained;
      ++n_1to1;
    }
  }
  if (n_1to1 > 0) {
    const std::string what = "probeless 1->1: " + std::to_string(lost_1to1) + " messages lost in " +
                             std::to_string(n_1to1) + " rows (target 0)";
    if (lost_1to1 != 0 && unexplained_1to1 == 0 &&
        counted_1to1 == static_cast<int64_t>(lost_1to1)) {
      std::printf(
          "  LOAD  %s: every one dropped by the subscriber's own full queue (bus counted %lld) "
          "after it fell a queue depth behind (descheduled by other load; --rt avoids it)\n",
          what.c_str(), static_cast<long long>(counted_1to1));
    } else {
      Check(&misses, lost_1to1 == 0,
            what + (lost_1to1 == 0 ? ""
                                   : ", bus counted " + std::to_string(counted_1to1) + ", " +
                                         std::to_string(unexplained_1to1) + " unexplained"));
    }
  }
  for (const Row& r : rows) {
    if (r.scenario == "4x_rgbd_30fps" && r.transport == "probeless") {
      Check(&misses, r.lost == 0,
            "probeless 4x_rgbd_30fps " + std::to_string(r.size) + " B: " + std::to_string(r.lost) +
                " drops over " + std::to_string(r.samples) + " deliveries (target 0)");
    }
    if (r.scenario == "slow_subscriber" && r.transport == "probeless") {
      const std::string publisher = "publisher never blocked (max Loan+Publish " +
                                    Fixed(r.max_publish_us, 1) + " us, loan failures " +
                                    std::to_string(r.loan_failures) + "), slow one missed " +
                                    std::to_string(r.slow_lost) + " (bus counted " +
                                    std::to_string(r.slow_transport_drops) + ")";
      const bool publisher_ok = r.loan_failures == 0 && r.max_publish_us < 1000;
      // A fast subscriber's miss is the bus's fault unless the bus dropped it from that
      // subscriber's own full queue (counted) while the subscriber itself took nothing for
      // (depth - 1) periods and was runnable but not running that long: then it was a slow
      // subscriber at that moment (descheduled by other load), and drop-oldest is its contract.
      if (r.lost != 0 && publisher_ok && r.fast_unexplained == 0) {
        std::printf(
            "  LOAD  probeless slow subscriber: the bus lost nothing; fast subscribers missed "
            "%llu, all dropped by their own full queues (bus counted %lld) while one took nothing "
            "for up to %.1f ms and waited %.1f ms on a run queue (descheduled by other load; "
            "--rt avoids it); %s\n",
            static_cast<unsigned long long>(r.lost), static_cast<long long>(r.fast_transport_drops),
            r.fast_max_gap_us / 1e3, r.fast_run_delay_us / 1e3, publisher.c_str());
      } else {
        std::string fast = "fast subscribers lost " + std::to_string(r.lost);
        if (r.lost != 0) {
          fast += " (" + std::to_string(r.fast_unexplained) + " not explained by own-queue drops " +
                  std::to_string(r.fast_transport_drops) + ", took nothing for up to " +
                  Fixed(r.fast_max_gap_us / 1e3, 1) + " ms, run-queue wait " +
                  Fixed(r.fast_run_delay_us / 1e3, 1) + " ms)";
        }
        Check(&misses, r.lost == 0 && publisher_ok,
              "probeless slow subscriber: " + fast + ", " + publisher);
      }
    }
  }
  return misses;
}

}  // namespace probeless::bus_bench
