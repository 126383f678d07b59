// The fields of /proc/<pid>/stat (proc(5)) that the supervisor, the benchmarks and the process
// tests read: state, parentage, CPU time and start time of one process.
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <optional>
#include <string_view>

namespace probeless::launch {

struct ProcStat {
  pid_t pid = 0;
  char state = '?';          // field 3: R, S, D, Z (zombie), X (dead), ...
  pid_t ppid = 0;            // field 4
  pid_t pgid = 0;            // field 5: process group
  uint64_t utime_ticks = 0;  // field 14: user CPU, clock ticks (sysconf(_SC_CLK_TCK) a second)
  uint64_t stime_ticks = 0;  // field 15: system CPU, clock ticks
  uint64_t start_ticks = 0;  // field 22: start time, clock ticks since boot

  // Not a zombie and not dead: the process still runs (or sleeps).
  bool Alive() const { return state != 'Z' && state != 'X'; }
  // User plus system CPU of all its threads so far, seconds.
  double CpuSeconds() const;
};

// Parses one line of /proc/<pid>/stat. The command name (field 2) may hold spaces and ')', so the
// fields are read after the last ')'. nullopt when the line does not have fields 1 to 22.
std::optional<ProcStat> ParseProcStat(std::string_view line);

// Reads /proc/<pid>/stat; nullopt once the process is gone (reaped) or the file is unreadable.
std::optional<ProcStat> ReadProcStat(pid_t pid);

}  // namespace probeless::launch
