// probeless: the command-line front end. Dispatches `probeless <command> [args...]` through a
// table.
#include <cstdio>
#include <cstring>
#include <string_view>

#include "commands.h"

namespace {

struct Command {
  const char* name;
  int (*run)(int argc, char** argv);  // argv[0] is the command name
  const char* help;                   // one line
};

constexpr Command kCommands[] = {
    {"launch", probeless::tools::RunLaunchCommand,
     "run a launch file: launch FILE [name:=value ...] [--sigterm-timeout S] [--sigkill-timeout "
     "S]"},
    {"topic", probeless::tools::RunTopicCommand, "inspect topics: topic list|info|hz|bw|echo ..."},
    {"bag", probeless::tools::RunBagCommand,
     "MCAP logs and datasets: bag info|record|play|convert ..."},
    {"clean", probeless::tools::RunCleanCommand,
     "remove shared-memory segments left by dead processes"},
};

void PrintUsage(std::FILE* out) {
  std::fprintf(out, "usage: probeless <command> [arguments]\n\ncommands:\n");
  for (const Command& command : kCommands) {
    std::fprintf(out, "  %-8s %s\n", command.name, command.help);
  }
  std::fprintf(out, "\n'probeless <command> --help' shows the options of a command.\n");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "probeless: missing command\n");
    PrintUsage(stderr);
    return 2;
  }
  const std::string_view name = argv[1];
  if (name == "-h" || name == "--help" || name == "help") {
    PrintUsage(stdout);
    return 0;
  }
  for (const Command& command : kCommands) {
    if (name == command.name) return command.run(argc - 1, argv + 1);
  }
  std::fprintf(stderr, "probeless: unknown command '%s'\n", argv[1]);
  PrintUsage(stderr);
  return 2;
}
