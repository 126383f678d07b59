// bus_bench: a private iox-roudi child process.
#include "roudi.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <thread>

namespace probeless::bus_bench {
namespace {

constexpr const char* kReadyLine = "RouDi is ready for clients";

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string LastLine(const std::string& text) {
  std::string last;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    // Drop ANSI colour codes of the iceoryx logger.
    std::string clean;
    for (size_t i = 0; i < line.size(); ++i) {
      if (line[i] == '\x1b') {
        while (i < line.size() && line[i] != 'm') ++i;
        continue;
      }
      clean += line[i];
    }
    if (!clean.empty()) last = clean;
  }
  return last;
}

}  // namespace

std::string RouDi::Config(const std::vector<size_t>& sizes) {
  std::vector<size_t> sorted = sizes;
  std::sort(sorted.begin(), sorted.end());
  sorted.erase(std::unique(sorted.begin(), sorted.end()), sorted.end());
  std::ostringstream out;
  out << "# bus_bench: one mempool per payload size of the run\n"
      << "[general]\nversion = 1\n\n[[segment]]\n";
  size_t previous = 0;
  for (size_t size : sorted) {
    // Room for the chunk header and 64-byte payload alignment.
    const size_t chunk = (size + 256 + 63) / 64 * 64;
    if (chunk == previous) continue;
    previous = chunk;
    // Enough chunks for 4 publishers x 3 subscribers x (queue 4 + 1 held) + loans.
    const size_t count = size <= 65536 ? 256 : (size <= 2'000'000 ? 80 : 32);
    out << "\n[[segment.mempool]]\nsize = " << chunk << "\ncount = " << count << "\n";
  }
  return out.str();
}

bool RouDi::Start(const std::vector<size_t>& sizes, std::string* reason) {
  char config_path[] = "/tmp/bus_bench_roudi_XXXXXX.toml";
  const int config_fd = mkstemps(config_path, 5);
  if (config_fd < 0) {
    *reason = "cannot create a temp file for the RouDi config";
    return false;
  }
  const std::string config = Config(sizes);
  if (write(config_fd, config.data(), config.size()) != static_cast<ssize_t>(config.size())) {
    close(config_fd);
    unlink(config_path);
    *reason = "cannot write the RouDi config";
    return false;
  }
  close(config_fd);
  config_path_ = config_path;
  char log_path[] = "/tmp/bus_bench_roudi_XXXXXX.log";
  const int log_fd = mkstemps(log_path, 4);
  if (log_fd < 0) {
    *reason = "cannot create a temp file for the RouDi log";
    return false;
  }
  log_path_ = log_path;

  const pid_t parent = getpid();
  pid_ = fork();
  if (pid_ < 0) {
    close(log_fd);
    *reason = "fork failed";
    return false;
  }
  if (pid_ == 0) {
    // If bus_bench dies, RouDi gets SIGINT and removes its shared memory.
    prctl(PR_SET_PDEATHSIG, SIGINT);
    if (getppid() != parent) _exit(1);
    dup2(log_fd, STDOUT_FILENO);
    dup2(log_fd, STDERR_FILENO);
    close(log_fd);
    execlp("iox-roudi", "iox-roudi", "-c", config_path_.c_str(), static_cast<char*>(nullptr));
    std::fprintf(stderr, "cannot execute iox-roudi (not installed? package 'iceoryx')\n");
    _exit(127);
  }
  close(log_fd);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (std::chrono::steady_clock::now() < deadline) {
    const std::string log = ReadFile(log_path_);
    if (log.find(kReadyLine) != std::string::npos) return true;
    int status = 0;
    if (waitpid(pid_, &status, WNOHANG) == pid_) {
      pid_ = -1;
      const std::string last = LastLine(log);
      *reason = "iox-roudi exited at start" + (last.empty() ? "" : ": " + last);
      Stop();
      return false;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  *reason = "iox-roudi was not ready within 10 s: " + LastLine(ReadFile(log_path_));
  Stop();
  return false;
}

void RouDi::Stop() {
  if (pid_ > 0) {
    kill(pid_, SIGINT);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    int status = 0;
    bool gone = false;
    while (std::chrono::steady_clock::now() < deadline) {
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        gone = true;
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    if (!gone) {
      kill(pid_, SIGKILL);
      waitpid(pid_, &status, 0);
    }
    pid_ = -1;
  }
  if (!config_path_.empty()) unlink(config_path_.c_str());
  if (!log_path_.empty()) unlink(log_path_.c_str());
  config_path_.clear();
  log_path_.clear();
}

}  // namespace probeless::bus_bench
