// Integration tests of `probeless launch`: run the real build/bin/probeless on launch files
// written to a temporary directory, with launch_test_child as the node executable.
#include <fcntl.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "probeless/launch/proc_stat.h"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::Not;

const std::string kProbeless = PROBELESS_BIN_DIR "/probeless";
const std::string kChild = PROBELESS_TEST_BIN_DIR "/launch_test_child";

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// True while `pid` exists and is not a zombie.
bool ProcessAlive(pid_t pid) {
  const std::optional<probeless::launch::ProcStat> stat = probeless::launch::ReadProcStat(pid);
  return stat && stat->Alive();
}

bool WaitUntilGone(pid_t pid, double timeout_s) {
  const auto start = Clock::now();
  while (SecondsSince(start) < timeout_s) {
    if (!ProcessAlive(pid)) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return !ProcessAlive(pid);
}

// The lines of `text` that start with `prefix`, each with its '\n' (output of one node, whose
// lines may interleave with other nodes' lines).
std::string LinesWithPrefix(const std::string& text, const std::string& prefix) {
  std::istringstream in(text);
  std::string line;
  std::string result;
  while (std::getline(in, line)) {
    if (line.starts_with(prefix)) result += line + "\n";
  }
  return result;
}

// A running `probeless` with its stdout/stderr captured.
class Probeless {
 public:
  Probeless(const std::vector<std::string>& args, const std::vector<std::string>& extra_env) {
    int out[2];
    int err[2];
    EXPECT_EQ(::pipe2(out, O_CLOEXEC), 0);
    EXPECT_EQ(::pipe2(err, O_CLOEXEC), 0);
    std::vector<std::string> argv_strings{kProbeless};
    argv_strings.insert(argv_strings.end(), args.begin(), args.end());
    std::vector<std::string> env_strings;
    for (char** e = environ; *e != nullptr; ++e) {
      const std::string entry = *e;
      const std::string name = entry.substr(0, entry.find('=') + 1);
      const bool overridden =
          std::any_of(extra_env.begin(), extra_env.end(),
                      [&](const std::string& x) { return x.starts_with(name); });
      if (!overridden) env_strings.push_back(entry);
    }
    env_strings.insert(env_strings.end(), extra_env.begin(), extra_env.end());
    std::vector<char*> argv;
    for (auto& s : argv_strings) argv.push_back(s.data());
    argv.push_back(nullptr);
    std::vector<char*> envp;
    for (auto& s : env_strings) envp.push_back(s.data());
    envp.push_back(nullptr);
    start_ = Clock::now();
    pid_ = ::fork();
    if (pid_ == 0) {
      ::dup2(out[1], 1);
      ::dup2(err[1], 2);
      ::execve(argv[0], argv.data(), envp.data());
      ::_exit(127);
    }
    ::close(out[1]);
    ::close(err[1]);
    out_fd_ = out[0];
    err_fd_ = err[0];
  }

  ~Probeless() {
    if (pid_ > 0 && !exited_) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    if (out_fd_ >= 0) ::close(out_fd_);
    if (err_fd_ >= 0) ::close(err_fd_);
  }

  pid_t pid() const { return pid_; }

  // Reads output until both pipes reach EOF and the process exits; SIGKILLs it after timeout_s.
  void Wait(double timeout_s) {
    const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                             std::chrono::duration<double>(timeout_s));
    while (out_fd_ >= 0 || err_fd_ >= 0) {
      std::vector<pollfd> fds;
      if (out_fd_ >= 0) fds.push_back({out_fd_, POLLIN, 0});
      if (err_fd_ >= 0) fds.push_back({err_fd_, POLLIN, 0});
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
      if (left.count() <= 0) {
        ADD_FAILURE() << "probeless did not finish within " << timeout_s << " s; stderr:\n" << err_;
        ::kill(pid_, SIGKILL);
        break;
      }
      ::poll(fds.data(), fds.size(), static_cast<int>(left.count()));
      for (const pollfd& p : fds) {
        if (p.revents == 0) continue;
        char buffer[4096];
        const ssize_t n = ::read(p.fd, buffer, sizeof(buffer));
        std::string& target = p.fd == out_fd_ ? out_ : err_;
        if (n > 0) {
          target.append(buffer, static_cast<size_t>(n));
        } else {
          int& fd = p.fd == out_fd_ ? out_fd_ : err_fd_;
          ::close(fd);
          fd = -1;
        }
      }
    }
    int status = 0;
    ::waitpid(pid_, &status, 0);
    elapsed_s_ = SecondsSince(start_);
    exited_ = true;
    status_ = status;
  }

  // Exit code, or 128 + signal.
  int code() const { return WIFEXITED(status_) ? WEXITSTATUS(status_) : 128 + WTERMSIG(status_); }
  const std::string& out() const { return out_; }
  const std::string& err() const { return err_; }
  double elapsed_s() const { return elapsed_s_; }

 private:
  pid_t pid_ = -1;
  int out_fd_ = -1;
  int err_fd_ = -1;
  bool exited_ = false;
  int status_ = 0;
  std::string out_;
  std::string err_;
  Clock::time_point start_;
  double elapsed_s_ = 0;
};

class SupervisorTest : public ::testing::Test {
 protected:
  void SetUp() override {
    char pattern[] = "/tmp/launch_supervisor_test.XXXXXX";
    ASSERT_NE(::mkdtemp(pattern), nullptr);
    dir_ = pattern;
    env_ = {"PROBELESS_LOG_DIR=" + dir_ + "/log",
            "PATH=" + std::string(PROBELESS_TEST_BIN_DIR) + ":" + std::getenv("PATH")};
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Write(const std::string& name, const std::string& text) {
    const std::string path = dir_ + "/" + name;
    std::ofstream(path) << text;
    return path;
  }

  std::string Read(const std::string& name) {
    std::ifstream in(dir_ + "/" + name);
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
  }

  int CountLines(const std::string& name) {
    const std::string text = Read(name);
    return static_cast<int>(std::count(text.begin(), text.end(), '\n'));
  }

  // Waits until dir_/name exists and returns the pid in it (0 on timeout).
  pid_t WaitForPidFile(const std::string& name, double timeout_s = 5) {
    const auto start = Clock::now();
    while (SecondsSince(start) < timeout_s) {
      std::ifstream in(dir_ + "/" + name);
      pid_t pid = 0;
      if (in >> pid && pid > 0) return pid;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    ADD_FAILURE() << "no pid file " << name;
    return 0;
  }

  // Runs `probeless launch <file> args...` to completion.
  std::unique_ptr<Probeless> Run(const std::string& launch_text, std::vector<std::string> args = {},
                                 double timeout_s = 10) {
    auto p = Start(launch_text, std::move(args));
    p->Wait(timeout_s);
    return p;
  }

  std::unique_ptr<Probeless> Start(const std::string& launch_text,
                                   std::vector<std::string> args = {}) {
    const std::string file = Write("test.launch.yaml", launch_text);
    args.insert(args.begin(), {"launch", file});
    return std::make_unique<Probeless>(args, env_);
  }

  std::string dir_;
  std::vector<std::string> env_;
};

TEST_F(SupervisorTest, OutputIsPrefixedLineByLine) {
  auto p = Run(R"yaml(launch:
- node: {exec: launch_test_child, name: alpha, args: "--print hello --stderr oops --print world"}
- node: {exec: launch_test_child, name: beta, output: log, args: "--print 'b one' --stderr 'b two'"}
)yaml");
  EXPECT_EQ(p->code(), 0) << p->err();
  EXPECT_EQ(LinesWithPrefix(p->out(), "[alpha] "), "[alpha] hello\n[alpha] world\n");
  EXPECT_EQ(LinesWithPrefix(p->out(), "[beta] "), "[beta] b one\n");
  EXPECT_THAT(p->err(), HasSubstr("[alpha] oops\n"));
  EXPECT_THAT(p->err(), HasSubstr("[beta] b two\n"));
  EXPECT_THAT(p->err(), HasSubstr("[probeless] alpha exited with code 0"));
  // output: log also writes the raw lines to <log dir>/<name>.log.
  const std::string log = Read("log/beta.log");
  EXPECT_THAT(log, HasSubstr("b one\n"));
  EXPECT_THAT(log, HasSubstr("b two\n"));
  EXPECT_FALSE(fs::exists(dir_ + "/log/alpha.log"));
}

TEST_F(SupervisorTest, SharedNamesAreLabelledWithTheirNamespace) {
  auto p = Run(R"yaml(launch:
- node: {exec: launch_test_child, name: cam, namespace: front, args: "--print f"}
- node: {exec: launch_test_child, name: cam, namespace: rear, args: "--print r"}
- node: {exec: launch_test_child, name: solo, namespace: rear, args: "--print s"}
)yaml");
  EXPECT_EQ(p->code(), 0) << p->err();
  EXPECT_THAT(p->out(), HasSubstr("[front/cam] f\n"));
  EXPECT_THAT(p->out(), HasSubstr("[rear/cam] r\n"));
  EXPECT_THAT(p->out(), HasSubstr("[solo] s\n"));
  EXPECT_THAT(p->err(), HasSubstr("[probeless] rear/cam exited with code 0"));
}

TEST_F(SupervisorTest, NodeFailureGivesExitCodeOne) {
  auto p = Run(R"yaml(launch:
- node: {exec: launch_test_child, name: ok}
- node: {exec: launch_test_child, name: bad, args: "--exit-code 3"}
)yaml");
  EXPECT_EQ(p->code(), 1);
  EXPECT_THAT(p->err(), HasSubstr("[probeless] bad exited with code 3"));
}

TEST_F(SupervisorTest, ArgumentOverridesAndNodeContract) {
  const std::string text = R"yaml(launch:
- arg: {name: greeting, default: hi}
- group:
    namespace: ns
    children:
    - node:
        exec: launch_test_child
        name: talker
        args: "--print $(arg greeting) --print-env PROBELESS_NODE_NAME --print-args"
        param: [{name: rate, value: 5}]
        remap: [{from: a, to: b}]
)yaml";
  auto p = Run(text, {"greeting:=bye"});
  EXPECT_EQ(p->code(), 0) << p->err();
  EXPECT_THAT(p->out(), HasSubstr("[talker] bye\n"));
  EXPECT_THAT(p->out(), HasSubstr("[talker] PROBELESS_NODE_NAME=/ns/talker\n"));
  EXPECT_THAT(p->out(), HasSubstr("[talker] arg: --ros-args\n[talker] arg: -r\n[talker] arg: "
                                  "__node:=talker\n[talker] arg: -r\n[talker] arg: __ns:=/ns\n"
                                  "[talker] arg: -p\n[talker] arg: rate:=5\n[talker] arg: -r\n"
                                  "[talker] arg: a:=b\n"));
  auto defaults = Run(text);
  EXPECT_THAT(defaults->out(), HasSubstr("[talker] hi\n"));
}

TEST_F(SupervisorTest, LaunchPrefix) {
  auto p = Run(R"yaml(launch:
- set_env: {name: FROM_SET_ENV, value: yes_set}
- node:
    exec: launch_test_child
    name: prefixed
    launch-prefix: "env FOO=1"
    env: [{name: BAR, value: "2 3"}]
    args: "--print-env FOO --print-env BAR --print-env FROM_SET_ENV"
)yaml");
  EXPECT_EQ(p->code(), 0) << p->err();
  EXPECT_THAT(p->out(), HasSubstr("[prefixed] FOO=1\n[prefixed] BAR=2 3\n"
                                  "[prefixed] FROM_SET_ENV=yes_set\n"));
}

TEST_F(SupervisorTest, RespawnStopsAfterMaxRetries) {
  const std::string count = dir_ + "/count";
  auto p = Run(R"yaml(launch:
- node:
    exec: launch_test_child
    name: flaky
    args: "--count-file )yaml" +
               count + R"yaml( --exit-code 1"
    respawn: true
    respawn_delay: 0.1
    respawn_max_retries: 3
)yaml");
  EXPECT_EQ(p->code(), 1);
  EXPECT_EQ(CountLines("count"), 4);  // first start + 3 restarts
  EXPECT_GE(p->elapsed_s(), 0.3);
  EXPECT_THAT(p->err(), HasSubstr("respawning in 0.1 s (restart 3 of 3)"));
  EXPECT_THAT(p->err(), HasSubstr("flaky exited with code 1 (no respawn retries left)"));
}

TEST_F(SupervisorTest, RespawnUntilRequiredNodeEndsTheLaunch) {
  const std::string count = dir_ + "/count";
  auto p = Run(R"yaml(launch:
- node:
    exec: launch_test_child
    name: looper
    args: "--count-file )yaml" +
               count + R"yaml("
    respawn: true
    respawn_delay: 0.1
- node: {exec: launch_test_child, name: boss, args: "--sleep 0.8", required: true}
)yaml");
  EXPECT_EQ(p->code(), 0) << p->err();  // the required node exited with 0
  EXPECT_GE(CountLines("count"), 3);
  EXPECT_LE(CountLines("count"), 12);
  EXPECT_THAT(p->err(), HasSubstr("required node boss finished; stopping"));
  EXPECT_LT(p->elapsed_s(), 4);
}

TEST_F(SupervisorTest, RequiredNodeFailureStopsTheGraph) {
  auto p = Run(R"yaml(launch:
- node: {exec: launch_test_child, name: worker, args: "--sleep 30"}
- node: {exec: launch_test_child, name: critical, args: "--sleep 0.3 --exit-code 4", on_exit: shutdown}
)yaml");
  EXPECT_EQ(p->code(), 1);
  EXPECT_THAT(p->err(), HasSubstr("critical exited with code 4"));
  EXPECT_THAT(p->err(), HasSubstr("required node critical finished; stopping"));
  EXPECT_THAT(p->err(), HasSubstr("worker was killed by signal SIGINT"));
  EXPECT_LT(p->elapsed_s(), 3);
}

TEST_F(SupervisorTest, ShutdownEscalation) {
  auto p = Start(
      "launch:\n"
      "- node: {exec: launch_test_child, name: polite, args: \"--pidfile " +
          dir_ +
          "/polite.pid --sleep 30\"}\n"
          "- node: {exec: launch_test_child, name: stubborn, args: \"--ignore-sigint "
          "--ignore-sigterm --pidfile " +
          dir_ +
          "/stubborn.pid --sleep 30\"}\n"
          "- node: {exec: launch_test_child, name: half, args: \"--ignore-sigint "
          "--pidfile " +
          dir_ + "/half.pid --sleep 30\"}\n",
      {"--sigterm-timeout", "0.5", "--sigkill-timeout=0.5"});
  for (const char* name : {"polite.pid", "stubborn.pid", "half.pid"}) WaitForPidFile(name);
  const auto interrupt = Clock::now();
  ASSERT_EQ(::kill(p->pid(), SIGINT), 0);
  p->Wait(10);
  const double took = SecondsSince(interrupt);
  EXPECT_EQ(p->code(), 0) << p->err();
  EXPECT_GE(took, 0.9);
  EXPECT_LT(took, 2.5);
  EXPECT_THAT(p->err(), HasSubstr("received SIGINT; stopping"));
  EXPECT_THAT(p->err(), HasSubstr("polite was killed by signal SIGINT"));
  EXPECT_THAT(p->err(), HasSubstr("sending SIGTERM to stubborn, half"));
  EXPECT_THAT(p->err(), HasSubstr("half was killed by signal SIGTERM"));
  EXPECT_THAT(p->err(), HasSubstr("sending SIGKILL to stubborn\n"));
  EXPECT_THAT(p->err(), HasSubstr("stubborn was killed by signal SIGKILL"));
}

TEST_F(SupervisorTest, SecondSignalSkipsAhead) {
  auto p = Start(
      "launch:\n- node: {exec: launch_test_child, name: stubborn, args: "
      "\"--ignore-sigint --ignore-sigterm --pidfile " +
      dir_ + "/s.pid --sleep 30\"}\n");  // default timeouts: 5 s + 5 s
  WaitForPidFile("s.pid");
  ASSERT_EQ(::kill(p->pid(), SIGTERM), 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  ASSERT_EQ(::kill(p->pid(), SIGTERM), 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  ASSERT_EQ(::kill(p->pid(), SIGINT), 0);
  p->Wait(5);
  EXPECT_LT(p->elapsed_s(), 3);
  EXPECT_THAT(p->err(), HasSubstr("stubborn was killed by signal SIGKILL"));
}

TEST_F(SupervisorTest, NoOrphansAfterShutdown) {
  auto p = Start(
      "launch:\n- node: {exec: launch_test_child, name: parent, args: "
      "\"--spawn-grandchild " +
      dir_ + "/g1.pid --spawn-grandchild-own-group " + dir_ + "/g2.pid --pidfile " + dir_ +
      "/p.pid --sleep 30\"}\n");
  const pid_t parent = WaitForPidFile("p.pid");
  const pid_t same_group = WaitForPidFile("g1.pid");
  const pid_t own_group = WaitForPidFile("g2.pid");
  ASSERT_TRUE(ProcessAlive(same_group));
  ASSERT_TRUE(ProcessAlive(own_group));
  ASSERT_EQ(::kill(p->pid(), SIGTERM), 0);
  p->Wait(10);
  EXPECT_EQ(p->code(), 0) << p->err();
  EXPECT_LT(p->elapsed_s(), 5);
  EXPECT_FALSE(ProcessAlive(parent));
  EXPECT_FALSE(ProcessAlive(same_group));
  EXPECT_FALSE(ProcessAlive(own_group));
}

TEST_F(SupervisorTest, LeftoversOfFinishedNodesAreStopped) {
  auto p =
      Run("launch:\n- node: {exec: launch_test_child, name: quitter, args: "
          "\"--spawn-grandchild-own-group " +
          dir_ + "/g.pid --exit-code 0\"}\n");
  EXPECT_EQ(p->code(), 0) << p->err();
  EXPECT_LT(p->elapsed_s(), 4);
  EXPECT_THAT(p->err(), HasSubstr("all nodes finished, 1 leftover process(es) remain"));
  const pid_t grandchild = WaitForPidFile("g.pid", 0.1);
  EXPECT_FALSE(ProcessAlive(grandchild));
}

TEST_F(SupervisorTest, NoOrphansWhenTheSupervisorIsKilled) {
  auto p = Start(
      "launch:\n- node: {exec: launch_test_child, name: parent, args: "
      "\"--ignore-sigint --ignore-sigterm --spawn-grandchild " +
      dir_ + "/g.pid --pidfile " + dir_ + "/p.pid --sleep 30\"}\n");
  const pid_t parent = WaitForPidFile("p.pid");
  const pid_t grandchild = WaitForPidFile("g.pid");
  ASSERT_TRUE(ProcessAlive(grandchild));
  ASSERT_EQ(::kill(p->pid(), SIGKILL), 0);
  p->Wait(5);
  EXPECT_EQ(p->code(), 128 + SIGKILL);
  EXPECT_TRUE(WaitUntilGone(parent, 2)) << "node survived the supervisor";
  EXPECT_TRUE(WaitUntilGone(grandchild, 2)) << "grandchild survived the supervisor";
}

TEST_F(SupervisorTest, MissingExecutableStartsNothing) {
  auto p = Run("launch:\n- node: {exec: launch_test_child, name: first, args: \"--count-file " +
               dir_ + "/count\"}\n- node: {exec: no_such_exe_here, name: ghost}\n");
  EXPECT_EQ(p->code(), 2);
  EXPECT_THAT(p->err(), HasSubstr("test.launch.yaml:3:16: node 'ghost': executable "
                                  "'no_such_exe_here' not found"));
  EXPECT_EQ(std::count(p->err().begin(), p->err().end(), '\n'), 1) << p->err();
  EXPECT_THAT(p->err(), Not(HasSubstr("started")));
  EXPECT_FALSE(fs::exists(dir_ + "/count"));
}

TEST_F(SupervisorTest, LaunchFileErrorsExitTwo) {
  auto p = Run("launch:\n- node: {exec: launch_test_child, respawn: sometimes}\n");
  EXPECT_EQ(p->code(), 2);
  EXPECT_THAT(p->err(), HasSubstr("test.launch.yaml:2:44: invalid boolean 'sometimes'"));
  auto unknown_arg = Run("launch: []\n", {"nope:=1"});
  EXPECT_EQ(unknown_arg->code(), 2);
  EXPECT_THAT(unknown_arg->err(), HasSubstr("unknown launch argument 'nope'"));
}

TEST_F(SupervisorTest, CommandLineErrors) {
  Probeless unknown({"frobnicate"}, env_);
  unknown.Wait(5);
  EXPECT_EQ(unknown.code(), 2);
  EXPECT_THAT(unknown.err(), AllOf(HasSubstr("probeless: unknown command 'frobnicate'\n"),
                                   HasSubstr("usage: probeless <command>")));
  Probeless none({}, env_);
  none.Wait(5);
  EXPECT_EQ(none.code(), 2);
  Probeless bad_option({"launch", "x.yaml", "--sigterm-timeout", "-1"}, env_);
  bad_option.Wait(5);
  EXPECT_EQ(bad_option.code(), 2);
  EXPECT_THAT(bad_option.err(), HasSubstr("invalid --sigterm-timeout '-1'"));
  Probeless missing({"launch"}, env_);
  missing.Wait(5);
  EXPECT_EQ(missing.code(), 2);
  EXPECT_THAT(missing.err(), HasSubstr("missing launch file"));
  Probeless help({"--help"}, env_);
  help.Wait(5);
  EXPECT_EQ(help.code(), 0);
  EXPECT_THAT(help.out(), HasSubstr("launch"));
}

TEST_F(SupervisorTest, DryRunPrintsCommandLines) {
  auto p = Run("launch:\n- node: {exec: launch_test_child, name: n1, args: \"--print 'a b'\"}\n",
               {"--dry-run"});
  EXPECT_EQ(p->code(), 0);
  EXPECT_THAT(p->out(), HasSubstr("/n1: PROBELESS_NODE_NAME=/n1 " + kChild +
                                  " --print 'a b' --ros-args -r __node:=n1 -r __ns:=/\n"));
}

}  // namespace
