// The launch supervisor: fork/exec of nodes, output relaying, respawn, shutdown escalation and
// orphan control. One event loop on poll() over a signalfd and the nodes' output pipes.
#include "probeless/launch/supervisor.h"

#include <dirent.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/signalfd.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include "probeless/error/error.h"
#include "probeless/launch/proc_stat.h"

extern char** environ;

namespace probeless::launch {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// A line longer than this without '\n' is relayed in pieces.
constexpr size_t kMaxLineBytes = 64 * 1024;
// Exit code reported for a node whose execve failed.
constexpr int kExecFailedCode = 127;

// Writes all of `data` to `fd`; gives up silently on errors other than EINTR/EAGAIN (a closed
// terminal must not stop the supervisor).
void WriteAll(int fd, std::string_view data) {
  while (!data.empty()) {
    const ssize_t n = ::write(fd, data.data(), data.size());
    if (n > 0) {
      data.remove_prefix(static_cast<size_t>(n));
    } else if (n < 0 && errno == EINTR) {
      continue;
    } else if (n < 0 && errno == EAGAIN) {
      pollfd p{fd, POLLOUT, 0};
      ::poll(&p, 1, 100);
    } else {
      return;
    }
  }
}

void Message(const std::string& text) { WriteAll(STDERR_FILENO, "[probeless] " + text + "\n"); }

std::string FormatSeconds(double seconds) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%g", seconds);
  return buffer;
}

std::string DescribeStatus(int status) {
  if (WIFEXITED(status)) return "exited with code " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    const char* name = sigabbrev_np(sig);
    return "was killed by signal " + std::string(name ? "SIG" + std::string(name) : "?") + " (" +
           std::to_string(sig) + ")";
  }
  return "stopped with status " + std::to_string(status);
}

bool StatusIsSuccess(int status) { return WIFEXITED(status) && WEXITSTATUS(status) == 0; }

// Process table row needed for descendant tracking.
struct ProcInfo {
  pid_t pid = 0;
  pid_t ppid = 0;
  pid_t pgid = 0;
};

std::vector<ProcInfo> ReadProcessTable() {
  std::vector<ProcInfo> table;
  DIR* dir = ::opendir("/proc");
  if (dir == nullptr) return table;
  while (dirent* entry = ::readdir(dir)) {
    if (!std::isdigit(static_cast<unsigned char>(entry->d_name[0]))) continue;
    const std::optional<ProcStat> stat = ReadProcStat(std::atoi(entry->d_name));
    if (!stat || !stat->Alive()) continue;  // gone since readdir, or a zombie
    table.push_back({stat->pid, stat->ppid, stat->pgid});
  }
  ::closedir(dir);
  return table;
}

// Living descendants of `root`, excluding the subtree of `excluded`.
std::vector<ProcInfo> Descendants(pid_t root, pid_t excluded) {
  const std::vector<ProcInfo> table = ReadProcessTable();
  std::vector<ProcInfo> result;
  std::vector<pid_t> frontier{root};
  while (!frontier.empty()) {
    const pid_t parent = frontier.back();
    frontier.pop_back();
    for (const ProcInfo& p : table) {
      if (p.ppid == parent && p.pid != excluded) {
        result.push_back(p);
        frontier.push_back(p.pid);
      }
    }
  }
  return result;
}

// The watchdog: a child of the supervisor that outlives it. It is told the process group of every
// node (int32 > 0 added, < 0 removed, 0 = clean exit). If its pipe reaches EOF without the clean
// exit mark, the supervisor died abruptly: it SIGKILLs every known group.
[[noreturn]] void RunWatchdog(int read_fd) {
  ::setpgid(0, 0);  // out of the terminal's foreground group
  ::signal(SIGINT, SIG_IGN);
  ::signal(SIGTERM, SIG_IGN);
  ::signal(SIGHUP, SIG_IGN);
  sigset_t none;
  sigemptyset(&none);
  ::sigprocmask(SIG_SETMASK, &none, nullptr);
  std::set<int32_t> groups;
  int32_t value = 0;
  size_t have = 0;
  while (true) {
    const ssize_t n = ::read(read_fd, reinterpret_cast<char*>(&value) + have, sizeof(value) - have);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    have += static_cast<size_t>(n);
    if (have < sizeof(value)) continue;
    have = 0;
    if (value == 0) ::_exit(0);
    if (value > 0) {
      groups.insert(value);
    } else {
      groups.erase(-value);
    }
  }
  for (int32_t group : groups) ::kill(-group, SIGKILL);
  ::_exit(0);
}

class Supervisor {
 public:
  Supervisor(const LaunchDescription& description, const SupervisorOptions& options)
      : description_(description), options_(options), self_(::getpid()) {
    nodes_.resize(description.nodes.size());
    for (size_t i = 0; i < nodes_.size(); ++i) {
      const NodeSpec& spec = description.nodes[i];
      nodes_[i].spec = &spec;
      // The name labels output and messages; a name shared by several nodes (in different
      // namespaces) is replaced by the fully qualified name without its leading '/'.
      const auto same_name =
          std::count_if(description.nodes.begin(), description.nodes.end(),
                        [&](const NodeSpec& other) { return other.name == spec.name; });
      nodes_[i].label = same_name > 1 ? spec.fully_qualified_name.substr(1) : spec.name;
    }
  }

  int Run() {
    Setup();
    for (size_t i = 0; i < nodes_.size(); ++i) Spawn(i);
    CheckAllDone();
    while (!finished_) {
      Loop();
    }
    Teardown();
    return failed_ ? 1 : 0;
  }

 private:
  enum class State { kRunning, kWaitingRespawn, kDone };

  struct Node {
    const NodeSpec* spec = nullptr;
    std::string label;  // "[<label>] " prefixes the node's output lines
    State state = State::kDone;
    pid_t pid = 0;
    int restarts = 0;
    Clock::time_point respawn_at;
    int log_fd = -1;
  };

  struct Stream {
    int fd = -1;
    size_t node = 0;
    bool is_stderr = false;
    std::string pending;
  };

  void Setup() {
    sigset_t mask;
    sigemptyset(&mask);
    for (int sig : {SIGINT, SIGTERM, SIGHUP, SIGCHLD}) sigaddset(&mask, sig);
    ::sigprocmask(SIG_BLOCK, &mask, &old_mask_);
    signal_fd_ = ::signalfd(-1, &mask, SFD_CLOEXEC | SFD_NONBLOCK);
    if (signal_fd_ < 0) throw std::system_error(errno, std::generic_category(), "launch: signalfd");
    struct sigaction ignore {};
    ignore.sa_handler = SIG_IGN;
    ::sigaction(SIGPIPE, &ignore, &old_sigpipe_);
    ::prctl(PR_GET_CHILD_SUBREAPER, &old_subreaper_);
    ::prctl(PR_SET_CHILD_SUBREAPER, 1);
    own_pgid_ = ::getpgrp();
    StartWatchdog();
    SetupLogDir();
  }

  void Teardown() {
    for (Stream& stream : streams_) {
      DrainStream(stream);
      FlushPartial(stream);
      ::close(stream.fd);
    }
    streams_.clear();
    for (Node& node : nodes_) {
      if (node.log_fd >= 0) ::close(node.log_fd);
      node.log_fd = -1;
    }
    if (watchdog_fd_ >= 0) {
      const int32_t done = 0;
      WriteAll(watchdog_fd_, std::string_view(reinterpret_cast<const char*>(&done), sizeof(done)));
      ::close(watchdog_fd_);
      int status = 0;
      while (::waitpid(watchdog_pid_, &status, 0) < 0 && errno == EINTR) {
      }
    }
    ::close(signal_fd_);
    ::prctl(PR_SET_CHILD_SUBREAPER, old_subreaper_);
    ::sigaction(SIGPIPE, &old_sigpipe_, nullptr);
    // Drop a SIGCHLD of our children still pending, so the caller does not see it. A pending
    // SIGINT/SIGTERM is left to the caller's disposition.
    sigset_t pending;
    sigpending(&pending);
    if (sigismember(&pending, SIGCHLD)) {
      timespec zero{0, 0};
      sigset_t chld;
      sigemptyset(&chld);
      sigaddset(&chld, SIGCHLD);
      ::sigtimedwait(&chld, nullptr, &zero);
    }
    ::sigprocmask(SIG_SETMASK, &old_mask_, nullptr);
  }

  void StartWatchdog() {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0) {
      Message("warning: no watchdog (pipe: " + std::string(std::strerror(errno)) + ")");
      return;
    }
    const pid_t pid = ::fork();
    if (pid == 0) {
      // Keep only the read end: stdout/stderr of a test harness must see EOF when we exit.
      const int null_fd = ::open("/dev/null", O_RDWR);
      for (int fd : {0, 1, 2}) ::dup2(null_fd, fd);
      ::dup2(fds[0], 3);
      ::close_range(4, ~0U, 0);
      RunWatchdog(3);
    }
    ::close(fds[0]);
    if (pid < 0) {
      Message("warning: no watchdog (fork: " + std::string(std::strerror(errno)) + ")");
      ::close(fds[1]);
      return;
    }
    watchdog_pid_ = pid;
    watchdog_fd_ = fds[1];
  }

  void TellWatchdog(int32_t value) {
    if (watchdog_fd_ < 0) return;
    WriteAll(watchdog_fd_, std::string_view(reinterpret_cast<const char*>(&value), sizeof(value)));
  }

  void SetupLogDir() {
    const bool any_log =
        std::any_of(description_.nodes.begin(), description_.nodes.end(),
                    [](const NodeSpec& n) { return n.output == OutputMode::kLog; });
    if (!any_log) return;
    log_dir_ = options_.log_dir;
    if (log_dir_.empty()) {
      if (const char* env = std::getenv("PROBELESS_LOG_DIR"); env != nullptr && *env != '\0') {
        log_dir_ = env;
      } else {
        const char* home = std::getenv("HOME");
        char stamp[64];
        const std::time_t now = std::time(nullptr);
        std::tm local{};
        ::localtime_r(&now, &local);
        std::strftime(stamp, sizeof(stamp), "%Y-%m-%d-%H-%M-%S", &local);
        log_dir_ = std::string(home != nullptr ? home : "/tmp") + "/.probeless/log/" + stamp + "-" +
                   std::to_string(self_);
      }
    }
    std::error_code error;
    fs::create_directories(log_dir_, error);
    if (error) {
      Message("warning: cannot create log directory " + log_dir_ + ": " + error.message());
    } else {
      Message("log files in " + log_dir_);
    }
  }

  int OpenLog(const NodeSpec& spec) {
    std::string file_name = spec.fully_qualified_name.substr(1);
    std::replace(file_name.begin(), file_name.end(), '/', '.');
    const std::string path = log_dir_ + "/" + file_name + ".log";
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    if (fd < 0) Message("warning: cannot open " + path + ": " + std::strerror(errno));
    return fd;
  }

  std::vector<std::string> BuildEnvironment(const NodeSpec& spec) {
    std::vector<std::string> env;
    for (char** e = environ; *e != nullptr; ++e) env.emplace_back(*e);
    for (const auto& [name, value] : spec.environment) {
      const std::string prefix = name + "=";
      std::erase_if(env, [&](const std::string& entry) { return entry.starts_with(prefix); });
      env.push_back(prefix + value);
    }
    return env;
  }

  static std::vector<char*> CStrings(std::vector<std::string>& strings) {
    std::vector<char*> pointers;
    for (auto& s : strings) pointers.push_back(s.data());
    pointers.push_back(nullptr);
    return pointers;
  }

  void Spawn(size_t index) {
    Node& node = nodes_[index];
    const NodeSpec& spec = *node.spec;
    std::vector<std::string> argv_strings = spec.prefix;
    argv_strings.insert(argv_strings.end(), spec.argv.begin(), spec.argv.end());
    std::vector<std::string> env_strings = BuildEnvironment(spec);
    std::vector<char*> argv = CStrings(argv_strings);
    std::vector<char*> envp = CStrings(env_strings);
    const char* program = argv_strings[0].c_str();

    if (spec.output == OutputMode::kLog && node.log_fd < 0 && !log_dir_.empty()) {
      node.log_fd = OpenLog(spec);
    }

    int out[2] = {-1, -1};
    int err[2] = {-1, -1};
    int exec_error[2] = {-1, -1};
    if (::pipe2(out, O_CLOEXEC) != 0 || ::pipe2(err, O_CLOEXEC) != 0 ||
        ::pipe2(exec_error, O_CLOEXEC) != 0) {
      const std::string reason = std::strerror(errno);
      for (int fd : {out[0], out[1], err[0], err[1], exec_error[0], exec_error[1]}) {
        if (fd >= 0) ::close(fd);
      }
      Message("cannot start " + node.label + ": pipe: " + reason);
      OnStartFailure(index);
      return;
    }
    const int null_fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
    const pid_t pid = ::fork();
    if (pid == 0) {
      // Child: only async-signal-safe calls from here on.
      ::setpgid(0, 0);
      ::prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (::getppid() != self_) ::_exit(kExecFailedCode);  // the supervisor already died
      ::dup2(null_fd >= 0 ? null_fd : 0, STDIN_FILENO);
      ::dup2(out[1], STDOUT_FILENO);
      ::dup2(err[1], STDERR_FILENO);
      struct sigaction dfl {};
      dfl.sa_handler = SIG_DFL;
      for (int sig : {SIGINT, SIGTERM, SIGHUP, SIGCHLD, SIGPIPE, SIGQUIT}) {
        ::sigaction(sig, &dfl, nullptr);
      }
      sigset_t none;
      sigemptyset(&none);
      ::sigprocmask(SIG_SETMASK, &none, nullptr);
      ::execve(program, argv.data(), envp.data());
      const int code = errno;
      ssize_t ignored = ::write(exec_error[1], &code, sizeof(code));
      (void)ignored;
      ::_exit(kExecFailedCode);
    }
    if (null_fd >= 0) ::close(null_fd);
    ::close(out[1]);
    ::close(err[1]);
    ::close(exec_error[1]);
    if (pid < 0) {
      const std::string reason = std::strerror(errno);
      ::close(out[0]);
      ::close(err[0]);
      ::close(exec_error[0]);
      Message("cannot start " + node.label + ": fork: " + reason);
      OnStartFailure(index);
      return;
    }
    ::setpgid(pid, pid);  // also in the parent, so signals reach the group right away
    TellWatchdog(pid);
    int code = 0;
    ssize_t n;
    do {
      n = ::read(exec_error[0], &code, sizeof(code));
    } while (n < 0 && errno == EINTR);
    ::close(exec_error[0]);

    node.pid = pid;
    node.state = State::kRunning;
    for (int fd : {out[0], err[0]}) ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) | O_NONBLOCK);
    streams_.push_back(Stream{out[0], index, false, {}});
    streams_.push_back(Stream{err[0], index, true, {}});
    if (n == sizeof(code)) {
      // The child exits with kExecFailedCode; its exit is handled like any other.
      Message("cannot start " + node.label + ": execve " + program + ": " + std::strerror(code));
    } else {
      Message("started " + node.label + " (pid " + std::to_string(pid) + ")");
    }
  }

  void OnStartFailure(size_t index) {
    nodes_[index].state = State::kDone;
    nodes_[index].pid = 0;
    HandleFinalExit(index, kExecFailedCode << 8);
  }

  void Loop() {
    std::vector<pollfd> fds;
    fds.push_back(pollfd{signal_fd_, POLLIN, 0});
    for (const Stream& stream : streams_) fds.push_back(pollfd{stream.fd, POLLIN, 0});
    int timeout_ms = -1;
    if (auto deadline = NextDeadline()) {
      const auto wait = std::chrono::ceil<std::chrono::milliseconds>(*deadline - Clock::now());
      timeout_ms = static_cast<int>(std::clamp<int64_t>(wait.count(), 0, 60'000));
    }
    const int ready = ::poll(fds.data(), fds.size(), timeout_ms);
    if (ready < 0 && errno != EINTR) {
      Message(std::string("poll failed: ") + std::strerror(errno));
      BeginShutdown("internal error");
      return;
    }
    // Streams first, so output written before an exit is relayed before its exit message.
    std::vector<int> closed;
    for (size_t i = 1; i < fds.size(); ++i) {
      if (fds[i].revents == 0) continue;
      auto it = std::find_if(streams_.begin(), streams_.end(),
                             [&](const Stream& s) { return s.fd == fds[i].fd; });
      PROBELESS_DEMAND(it != streams_.end(), "poll reported a descriptor that is no stream");
      if (!ReadStream(*it)) closed.push_back(it->fd);
    }
    for (int fd : closed) {
      auto it = std::find_if(streams_.begin(), streams_.end(),
                             [&](const Stream& s) { return s.fd == fd; });
      FlushPartial(*it);
      ::close(it->fd);
      streams_.erase(it);
    }
    if (fds[0].revents != 0) HandleSignals();
    HandleTimers();
    CheckAllDone();
  }

  std::optional<Clock::time_point> NextDeadline() const {
    std::optional<Clock::time_point> next;
    auto consider = [&](Clock::time_point t) {
      if (!next || t < *next) next = t;
    };
    for (const Node& node : nodes_) {
      if (node.state == State::kWaitingRespawn) consider(node.respawn_at);
    }
    if (shutdown_phase_ > 0 && shutdown_phase_ < 3) consider(next_escalation_);
    return next;
  }

  // Reads what is available; false at EOF.
  bool ReadStream(Stream& stream) {
    char buffer[16384];
    while (true) {
      const ssize_t n = ::read(stream.fd, buffer, sizeof(buffer));
      if (n > 0) {
        stream.pending.append(buffer, static_cast<size_t>(n));
        EmitLines(stream);
        if (static_cast<size_t>(n) < sizeof(buffer)) return true;
        continue;
      }
      if (n < 0 && errno == EINTR) continue;
      if (n < 0 && errno == EAGAIN) return true;
      return false;  // EOF or error
    }
  }

  void DrainStream(Stream& stream) {
    while (ReadStream(stream)) {
      pollfd p{stream.fd, POLLIN, 0};
      if (::poll(&p, 1, 0) <= 0) return;
    }
  }

  void EmitLine(const Stream& stream, std::string_view line) {
    const Node& node = nodes_[stream.node];
    std::string text = "[" + node.label + "] ";
    text.append(line);
    text += '\n';
    WriteAll(stream.is_stderr ? STDERR_FILENO : STDOUT_FILENO, text);
    if (node.log_fd >= 0) {
      WriteAll(node.log_fd, std::string(line) + "\n");
    }
  }

  void EmitLines(Stream& stream) {
    size_t start = 0;
    while (true) {
      const size_t newline = stream.pending.find('\n', start);
      if (newline == std::string::npos) break;
      EmitLine(stream, std::string_view(stream.pending).substr(start, newline - start));
      start = newline + 1;
    }
    stream.pending.erase(0, start);
    while (stream.pending.size() >= kMaxLineBytes) {
      EmitLine(stream, std::string_view(stream.pending).substr(0, kMaxLineBytes));
      stream.pending.erase(0, kMaxLineBytes);
    }
  }

  void FlushPartial(Stream& stream) {
    if (!stream.pending.empty()) EmitLine(stream, stream.pending);
    stream.pending.clear();
  }

  void HandleSignals() {
    signalfd_siginfo info{};
    while (::read(signal_fd_, &info, sizeof(info)) == static_cast<ssize_t>(sizeof(info))) {
      const int sig = static_cast<int>(info.ssi_signo);
      if (sig == SIGCHLD) {
        Reap();
      } else if (shutdown_phase_ == 0) {
        BeginShutdown(std::string("received SIG") + sigabbrev_np(sig));
      } else if (shutdown_phase_ < 3) {
        Message(std::string("received SIG") + sigabbrev_np(sig) + " again");
        Escalate();
      }
    }
    Reap();  // SIGCHLD may have been coalesced with a signal read above
  }

  void Reap() {
    while (true) {
      int status = 0;
      const pid_t pid = ::waitpid(-1, &status, WNOHANG);
      if (pid <= 0) break;
      if (pid == watchdog_pid_) {
        Message("warning: watchdog " + DescribeStatus(status));
        watchdog_pid_ = -1;
        if (watchdog_fd_ >= 0) ::close(watchdog_fd_);
        watchdog_fd_ = -1;
        continue;
      }
      auto it = std::find_if(nodes_.begin(), nodes_.end(), [&](const Node& n) {
        return n.state == State::kRunning && n.pid == pid;
      });
      if (it == nodes_.end()) continue;  // an orphan reparented to us
      OnNodeExit(static_cast<size_t>(it - nodes_.begin()), status);
    }
    // Forget groups that have no member left (their ids may be reused).
    for (auto it = lingering_groups_.begin(); it != lingering_groups_.end();) {
      if (::kill(-*it, 0) != 0 && errno == ESRCH) {
        TellWatchdog(-*it);
        it = lingering_groups_.erase(it);
      } else {
        ++it;
      }
    }
  }

  void OnNodeExit(size_t index, int status) {
    Node& node = nodes_[index];
    const NodeSpec& spec = *node.spec;
    lingering_groups_.insert(node.pid);
    node.pid = 0;
    node.state = State::kDone;
    if (shutdown_phase_ > 0) {
      Message(node.label + " " + DescribeStatus(status));
      return;
    }
    const bool can_respawn =
        spec.respawn && (spec.respawn_max_retries < 0 || node.restarts < spec.respawn_max_retries);
    if (can_respawn) {
      node.state = State::kWaitingRespawn;
      node.respawn_at = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                           std::chrono::duration<double>(spec.respawn_delay_s));
      std::string limit = spec.respawn_max_retries < 0
                              ? std::string()
                              : " of " + std::to_string(spec.respawn_max_retries);
      Message(node.label + " " + DescribeStatus(status) + "; respawning in " +
              FormatSeconds(spec.respawn_delay_s) + " s (restart " +
              std::to_string(node.restarts + 1) + limit + ")");
      return;
    }
    Message(node.label + " " + DescribeStatus(status) +
            (spec.respawn ? " (no respawn retries left)" : ""));
    HandleFinalExit(index, status);
  }

  // A node finished for good outside of a shutdown.
  void HandleFinalExit(size_t index, int status) {
    const Node& node = nodes_[index];
    if (shutdown_phase_ > 0) return;
    if (!StatusIsSuccess(status)) failed_ = true;
    if (node.spec->required) BeginShutdown("required node " + node.label + " finished");
  }

  void HandleTimers() {
    const auto now = Clock::now();
    for (size_t i = 0; i < nodes_.size(); ++i) {
      if (nodes_[i].state == State::kWaitingRespawn && nodes_[i].respawn_at <= now) {
        ++nodes_[i].restarts;
        Spawn(i);
      }
    }
    if (shutdown_phase_ > 0 && shutdown_phase_ < 3 && next_escalation_ <= now) Escalate();
  }

  // Process groups and lone processes to signal: running nodes, groups of exited nodes with
  // members left, and every descendant (orphans reparented to us, grandchildren in own groups).
  void SignalEverything(int sig) {
    std::set<pid_t> groups;
    for (const Node& node : nodes_) {
      if (node.state == State::kRunning) groups.insert(node.pid);
    }
    groups.insert(lingering_groups_.begin(), lingering_groups_.end());
    std::set<pid_t> lone;
    for (const ProcInfo& p : Descendants(self_, watchdog_pid_)) {
      if (p.pgid != own_pgid_ && p.pgid != watchdog_pid_) {
        groups.insert(p.pgid);
      } else {
        lone.insert(p.pid);
      }
    }
    for (pid_t group : groups) ::kill(-group, sig);
    for (pid_t pid : lone) ::kill(pid, sig);
    if (sig != SIGKILL) {
      // A stopped process acts on SIGINT/SIGTERM only once continued.
      for (pid_t group : groups) ::kill(-group, SIGCONT);
      for (pid_t pid : lone) ::kill(pid, SIGCONT);
    }
  }

  void BeginShutdown(const std::string& reason) {
    if (shutdown_phase_ > 0) return;
    Message(reason + "; stopping (SIGINT, SIGTERM after " +
            FormatSeconds(options_.sigterm_timeout_s) + " s, SIGKILL " +
            FormatSeconds(options_.sigkill_timeout_s) + " s later)");
    for (Node& node : nodes_) {
      if (node.state == State::kWaitingRespawn) node.state = State::kDone;
    }
    shutdown_phase_ = 1;
    SignalEverything(SIGINT);
    next_escalation_ =
        Clock::now() + std::chrono::duration_cast<Clock::duration>(
                           std::chrono::duration<double>(options_.sigterm_timeout_s));
  }

  void Escalate() {
    if (shutdown_phase_ == 1) {
      shutdown_phase_ = 2;
      Message("sending SIGTERM to " + StillRunning());
      SignalEverything(SIGTERM);
      next_escalation_ =
          Clock::now() + std::chrono::duration_cast<Clock::duration>(
                             std::chrono::duration<double>(options_.sigkill_timeout_s));
    } else if (shutdown_phase_ == 2) {
      shutdown_phase_ = 3;
      Message("sending SIGKILL to " + StillRunning());
      SignalEverything(SIGKILL);
    }
  }

  std::string StillRunning() const {
    std::string names;
    for (const Node& node : nodes_) {
      if (node.state == State::kRunning) names += (names.empty() ? "" : ", ") + node.label;
    }
    return names.empty() ? "leftover processes" : names;
  }

  // Ends the loop once no node runs or waits for a respawn and no descendant is left; stops
  // leftovers of finished nodes.
  void CheckAllDone() {
    const bool nodes_active = std::any_of(nodes_.begin(), nodes_.end(),
                                          [](const Node& n) { return n.state != State::kDone; });
    if (nodes_active) return;
    const std::vector<ProcInfo> left = Descendants(self_, watchdog_pid_);
    if (left.empty()) {
      finished_ = true;
      return;
    }
    if (shutdown_phase_ == 0) {
      BeginShutdown("all nodes finished, " + std::to_string(left.size()) +
                    " leftover process(es) remain");
    }
  }

  const LaunchDescription& description_;
  SupervisorOptions options_;
  const pid_t self_;
  pid_t own_pgid_ = 0;
  std::vector<Node> nodes_;
  std::vector<Stream> streams_;
  std::set<pid_t> lingering_groups_;
  int signal_fd_ = -1;
  sigset_t old_mask_{};
  struct sigaction old_sigpipe_ {};
  int old_subreaper_ = 0;
  pid_t watchdog_pid_ = -1;
  int watchdog_fd_ = -1;
  std::string log_dir_;
  int shutdown_phase_ = 0;  // 0 none, 1 SIGINT sent, 2 SIGTERM sent, 3 SIGKILL sent
  Clock::time_point next_escalation_;
  bool failed_ = false;
  bool finished_ = false;
};

}  // namespace

int RunSupervisor(const LaunchDescription& description, const SupervisorOptions& options) {
  return Supervisor(description, options).Run();
}

}  // namespace probeless::launch
