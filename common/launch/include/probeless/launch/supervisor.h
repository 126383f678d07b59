// The launch supervisor: runs the nodes of a LaunchDescription as child processes and owns them
// until every one of them (and every process they started) is gone.
//
// - Each node runs in its own process group; the supervisor is a child subreaper
//   (PR_SET_CHILD_SUBREAPER), so processes orphaned by a node are reparented to it and reaped.
// - Children get PR_SET_PDEATHSIG(SIGKILL); a watchdog process kills the nodes' process groups if
//   the supervisor itself dies (even by SIGKILL), so no grandchild survives it either.
// - stdout/stderr of every node go through pipes; each line is written to the supervisor's
//   stdout/stderr prefixed with "[<name>] " (and to a log file for output: log).
// - Shutdown (SIGINT/SIGTERM/SIGHUP to the supervisor, or a `required` node exiting): SIGINT to
// every
//   node's process group, SIGTERM after sigterm_timeout, SIGKILL sigkill_timeout later; processes
//   left over by nodes get the same escalation. A repeated signal to the supervisor skips ahead one
//   step.
// - Supervisor messages go to stderr prefixed with "[probeless] ".
#pragma once

#include <string>

#include "probeless/launch/launch.h"

namespace probeless::launch {

struct SupervisorOptions {
  double sigterm_timeout_s = 5.0;  // seconds from SIGINT to SIGTERM
  double sigkill_timeout_s = 5.0;  // seconds from SIGTERM to SIGKILL
  // Directory for output: log files; empty = $PROBELESS_LOG_DIR, else
  // ~/.probeless/log/<YYYY-mm-dd-HH-MM-SS>-<pid>/.
  std::string log_dir;
};

// Runs `description` to completion. Returns the process exit code of the launch:
//   0 when every node finished with exit code 0, or was stopped by a shutdown;
//   1 when a node exited non-zero or by a signal on its own (and was not respawned), which
//     includes a `required` node failing (that also shuts the graph down).
// A node that cannot be started (fork/pipe failure, execve error such as EACCES) counts as a node
// that exited with code 127 (a failure). Must be called from a single-threaded process; it blocks
// SIGINT/SIGTERM/SIGHUP/SIGCHLD, ignores SIGPIPE and becomes a child subreaper for its duration.
int RunSupervisor(const LaunchDescription& description, const SupervisorOptions& options);

}  // namespace probeless::launch
