// launch_test_child: a tiny node for supervisor tests. Flags are processed in order; everything
// from "--ros-args" on is the supervisor's contract and is only printed (--print-args).
//
//   --print TEXT             print TEXT as a line on stdout
//   --stderr TEXT            print TEXT as a line on stderr
//   --print-args             print every argument after the program name as "arg: <value>"
//   --print-env NAME         print "NAME=<value>" (or "NAME unset")
//   --count-file FILE        append "start <pid>" to FILE (counts restarts)
//   --pidfile FILE           write the own pid to FILE (atomically, after the flags before it)
//   --ignore-sigint          ignore SIGINT (inherited by grandchildren)
//   --ignore-sigterm         ignore SIGTERM (inherited by grandchildren)
//   --spawn-grandchild FILE  fork a child (same process group) sleeping 60 s; its pid -> FILE
//   --spawn-grandchild-own-group FILE   the same, but the grandchild calls setpgid(0, 0)
//   --sleep S                sleep S seconds (ignored signals do not cut it short)
//   --exit-code N            exit with N (default 0)
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <thread>

namespace {

void WriteFileAtomically(const std::string& path, const std::string& text) {
  const std::string temporary = path + ".tmp";
  {
    std::ofstream out(temporary);
    out << text;
  }
  std::rename(temporary.c_str(), path.c_str());
}

void SleepSeconds(double seconds) {
  const auto end = std::chrono::steady_clock::now() +
                   std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                       std::chrono::duration<double>(seconds));
  while (std::chrono::steady_clock::now() < end) {
    std::this_thread::sleep_until(end);
  }
}

void SpawnGrandchild(const std::string& pidfile, bool own_group) {
  const pid_t pid = ::fork();
  if (pid < 0) {
    std::perror("fork");
    std::exit(3);
  }
  if (pid == 0) {
    if (own_group) ::setpgid(0, 0);
    // Keeps the node's output pipes open, like a careless daemon would.
    SleepSeconds(60);
    std::_Exit(0);
  }
  WriteFileAtomically(pidfile, std::to_string(pid) + "\n");
}

}  // namespace

int main(int argc, char** argv) {
  int exit_code = 0;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--ros-args") break;
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "launch_test_child: %s needs a value\n", flag.c_str());
        std::exit(64);
      }
      return argv[++i];
    };
    if (flag == "--print") {
      std::printf("%s\n", value().c_str());
      std::fflush(stdout);
    } else if (flag == "--stderr") {
      std::fprintf(stderr, "%s\n", value().c_str());
    } else if (flag == "--print-args") {
      for (int j = 1; j < argc; ++j) std::printf("arg: %s\n", argv[j]);
      std::fflush(stdout);
    } else if (flag == "--print-env") {
      const std::string name = value();
      const char* env = std::getenv(name.c_str());
      if (env != nullptr) {
        std::printf("%s=%s\n", name.c_str(), env);
      } else {
        std::printf("%s unset\n", name.c_str());
      }
      std::fflush(stdout);
    } else if (flag == "--count-file") {
      std::ofstream(value(), std::ios::app) << "start " << ::getpid() << "\n";
    } else if (flag == "--pidfile") {
      WriteFileAtomically(value(), std::to_string(::getpid()) + "\n");
    } else if (flag == "--ignore-sigint") {
      ::signal(SIGINT, SIG_IGN);
    } else if (flag == "--ignore-sigterm") {
      ::signal(SIGTERM, SIG_IGN);
    } else if (flag == "--spawn-grandchild") {
      SpawnGrandchild(value(), false);
    } else if (flag == "--spawn-grandchild-own-group") {
      SpawnGrandchild(value(), true);
    } else if (flag == "--sleep") {
      SleepSeconds(std::atof(value().c_str()));
    } else if (flag == "--exit-code") {
      exit_code = std::atoi(value().c_str());
    } else {
      std::fprintf(stderr, "launch_test_child: unknown flag %s\n", flag.c_str());
      return 64;
    }
  }
  return exit_code;
}
