// bus_bench: result rows, the readable table, the JSON file and the target checks.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace probeless::bus_bench {

// One result row. Latencies in microseconds; -1 in an optional field means "not measured".
struct Row {
  std::string transport;  // probeless | uds | iceoryx
  std::string scenario;   // 1to1 | 1to3 | slow_subscriber | 4x_rgbd_30fps
  std::string mode;       // blocking | busy
  uint64_t size = 0;      // payload bytes
  uint32_t subscribers = 0;
  bool write_payload = false;
  double rate_hz = 0;    // pacing of the latency run
  uint64_t samples = 0;  // latency samples (all fast subscribers, warm-up excluded)
  double p50_us = 0, p90_us = 0, p99_us = 0, p999_us = 0, max_us = 0;
  double msgs_per_s = 0;  // throughput (unpaced run; scenarios: delivered rate)
  double mb_per_s = 0;
  uint64_t lost = 0;  // messages a fast subscriber did not get (latency + throughput runs)
  // What the losses were (see Accumulate in main.cpp): `counted_drops` of them counted by the
  // transport itself (-1: it does not count them), `unexplained` neither counted nor the
  // documented queue policy of a subscriber that fell a queue depth behind: the transport's or
  // the harness's fault (target 0 under any load).
  int64_t counted_drops = 0;
  int64_t unexplained = 0;
  int64_t reordered = 0;  // messages taken with a sequence number not above the previous one
  // Extras.
  double max_publish_us = -1;  // longest Loan + Publish call in the latency run
  int64_t loan_failures = 0;
  int64_t checksum_errors = 0;
  int64_t stale = 0;
  int64_t slow_received = -1;         // slow_subscriber: what the slow one got …
  int64_t slow_lost = -1;             // … and missed (sequence gaps)
  int64_t slow_transport_drops = -1;  // … as counted by the transport itself (-1: not counted)
  // slow_subscriber: what the fast subscribers' misses (`lost`) were. `fast_transport_drops` of
  // them were drops of the fast subscribers' own full queues counted by the transport (-1: it
  // does not count); `fast_max_gap_us` is the longest a fast subscriber went without taking a
  // message and `fast_run_delay_us` the longest run-queue wait of one (-1: not measured). A
  // subscriber that took nothing for (depth - 1) periods and waited that long on a run queue was
  // itself slow (descheduled): the bus drops for it by its queue policy, which is not a loss of a
  // fast subscriber. `fast_unexplained` counts every other miss of a fast subscriber: the bus's
  // (target 0).
  int64_t fast_transport_drops = -1;
  double fast_max_gap_us = -1;
  double fast_run_delay_us = -1;
  int64_t fast_unexplained = -1;
};

// Latency of a bare cross-process hand-over on this machine (no transport), microseconds.
struct WakeFloor {
  double futex_p50_us = 0, futex_p99_us = 0;  // waiter blocked in FUTEX_WAIT
  double spin_p50_us = 0, spin_p99_us = 0;    // waiter spinning
};

// Percentile (nearest rank) of sorted values; q in (0, 1].
double Percentile(const std::vector<int64_t>& sorted, double q);
// Fills p50…max from latency samples in nanoseconds (sorts them).
void SetLatencies(Row& row, std::vector<int64_t> latencies_ns);

void PrintTableHeader();
void PrintRow(const Row& row);
// Writes the rows as a JSON array; returns false with a message on I/O failure.
bool WriteJson(const std::string& path, const std::vector<Row>& rows, std::string* error);
// Prints PASS/MISS lines for the targets (and INFO lines putting them in context of the wake-up
// floor and busy-poll figures); returns the number of MISSes.
int PrintTargetChecks(const std::vector<Row>& rows, const WakeFloor& floor);

}  // namespace probeless::bus_bench
