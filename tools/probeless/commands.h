// Subcommands of the `probeless` command-line tool. Each takes the arguments after the subcommand
// name (argv[0] is the subcommand name itself) and returns the process exit code: 0 success,
// 1 failure at run time, 2 usage or input error. Each prints its own errors as one line to stderr.
#pragma once

namespace probeless::tools {

// `probeless launch FILE [name:=value ...] [options]`: runs a launch file (launch_command.cpp).
int RunLaunchCommand(int argc, char** argv);

// `probeless topic ...`: topic introspection (topic_command.cpp).
int RunTopicCommand(int argc, char** argv);

// `probeless clean`: removes shared-memory leftovers of dead processes (topic_command.cpp).
int RunCleanCommand(int argc, char** argv);

// `probeless bag info|record|play|convert`: MCAP logs and dataset sources (bag_command.cpp).
int RunBagCommand(int argc, char** argv);

}  // namespace probeless::tools
