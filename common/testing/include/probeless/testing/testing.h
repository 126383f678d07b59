// Helpers shared by the probeless tests (target probeless_testing, header-only, tests only): a
// temporary directory per test, whole text files, shell command lines and child processes with
// their stdout and stderr captured. Assertions on thrown exceptions are in expect.h (included).
#pragma once

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "probeless/testing/expect.h"

extern char** environ;

namespace probeless::testing {

// The whole file `path` as text ("" if it cannot be read).
inline std::string ReadText(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// Writes `text` to `path`, replacing it.
inline void WriteText(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
}

// A fresh directory for one test, <gtest temp dir>/<prefix>_<pid>_<suite>_<test>, removed at the
// end. Construct it inside a test (it names itself after the running test).
class TempDir {
 public:
  explicit TempDir(std::string_view prefix) {
    std::string name = std::string(prefix) + "_" + std::to_string(::getpid());
    if (const auto* info = ::testing::UnitTest::GetInstance()->current_test_info()) {
      name += std::string("_") + info->test_suite_name() + "_" + info->name();
    }
    for (char& c : name) {
      if (c == '/') c = '_';
    }
    path_ = std::filesystem::path(::testing::TempDir()) / name;
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  std::string path() const { return path_.string(); }
  // `name` under the directory, creating its parent folders.
  std::string File(const std::string& name) const {
    const std::filesystem::path file = path_ / name;
    std::filesystem::create_directories(file.parent_path());
    return file.string();
  }

 private:
  std::filesystem::path path_;
};

// What a finished command printed and returned.
struct CommandResult {
  int code = -1;  // exit code, -1 if it did not exit normally
  std::string out;
  std::string err;
  double seconds = 0;  // wall time
};

// Runs the shell command line `command` (stdin from /dev/null) and captures stdout and stderr
// through files stdout.txt and stderr.txt in `scratch_dir`.
inline CommandResult RunCommand(const std::string& command,
                                const std::filesystem::path& scratch_dir) {
  const std::filesystem::path out = scratch_dir / "stdout.txt";
  const std::filesystem::path err = scratch_dir / "stderr.txt";
  const auto start = std::chrono::steady_clock::now();
  const int status =
      std::system((command + " < /dev/null > " + out.string() + " 2> " + err.string()).c_str());
  CommandResult result;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  result.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  result.out = ReadText(out);
  result.err = ReadText(err);
  return result;
}

// A child process (an executable of build/bin, run with this process' environment) whose stdout
// and stderr go to files /tmp/probeless_<exe>_<pid>_<n>.out|.err; killed (SIGKILL) and the files
// removed when destroyed.
class Process {
 public:
  // Starts PROBELESS_BIN_DIR/<exe> with `args` (a failure to start is a test failure).
  Process(const std::string& exe, std::vector<std::string> args) {
    static int counter = 0;
    const std::string base = "/tmp/probeless_" + exe + "_" + std::to_string(::getpid()) + "_" +
                             std::to_string(counter++);
    out_path_ = base + ".out";
    err_path_ = base + ".err";
    args.insert(args.begin(), std::string(PROBELESS_BIN_DIR) + "/" + exe);
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out_path_.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0600);
    posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err_path_.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0600);
    const int rc = posix_spawn(&pid_, argv[0], &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    EXPECT_EQ(rc, 0) << "cannot start " << argv[0];
  }
  ~Process() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      Wait();
    }
    std::filesystem::remove(out_path_);
    std::filesystem::remove(err_path_);
  }
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;

  void Signal(int signal_number) const { kill(pid_, signal_number); }
  // Waits for the exit (at most `timeout`, then SIGKILL) and returns the exit code (-1 if killed).
  int Wait(std::chrono::milliseconds timeout = std::chrono::seconds(10)) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    int status = 0;
    while (waitpid(pid_, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() > deadline) {
        kill(pid_, SIGKILL);
        waitpid(pid_, &status, 0);
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    pid_ = -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  std::string Out() const { return ReadText(out_path_); }
  std::string Err() const { return ReadText(err_path_); }

 private:
  pid_t pid_ = -1;
  std::string out_path_;
  std::string err_path_;
};

}  // namespace probeless::testing
