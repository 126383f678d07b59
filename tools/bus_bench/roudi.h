// bus_bench: starts and stops a private iox-roudi (iceoryx 2.0 daemon) for the iceoryx rows.
#pragma once

#include <sys/types.h>

#include <cstddef>
#include <string>
#include <vector>

namespace probeless::bus_bench {

class RouDi {
 public:
  RouDi() = default;
  ~RouDi() { Stop(); }
  RouDi(const RouDi&) = delete;
  RouDi& operator=(const RouDi&) = delete;

  // Writes a RouDi TOML config with a mempool for every payload size in `sizes` (bytes) to a temp
  // file and starts `iox-roudi -c <file>` as a child; waits up to 10 s for "ready". Returns false
  // with a one-line `reason` if it cannot start (binary missing, another RouDi running, …).
  bool Start(const std::vector<size_t>& sizes, std::string* reason);
  // SIGINT (RouDi then removes its shared memory), waits up to 5 s, SIGKILL after that.
  void Stop();
  pid_t pid() const { return pid_; }

  // The TOML config for `sizes`: one mempool per size (chunk = size + header room, 64-aligned).
  static std::string Config(const std::vector<size_t>& sizes);

 private:
  pid_t pid_ = -1;
  std::string config_path_;
  std::string log_path_;
};

}  // namespace probeless::bus_bench
