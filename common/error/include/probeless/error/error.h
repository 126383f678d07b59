// The one error policy of every library, node and tool (docs/ARCHITECTURE.md "Errors").
//
// - Bad input at a boundary — a malformed file or message, an unknown option, an out-of-range
//   number, a missing device — throws a subclass of InputError with a one-line message naming the
//   thing and what was expected. node::RunMain prints it and exits with code 2.
// - A broken invariant of our own code (a reference count below zero, a slot index past the
//   mapping) is a bug, not input: PROBELESS_DEMAND reports it and aborts, in every build type.
//
//   if (width == 0) throw RenderError("renderer: width 0 (expected > 0)");   // RenderError :
//   InputError PROBELESS_DEMAND(slot < slot_count, "slot index past the mapping");
#pragma once

#include <cstdio>
#include <cstdlib>
#include <stdexcept>

namespace probeless {

// Base of every exception for bad input at a boundary: what() is the one-line message for the
// user. Processes exit with code 2 on it (node::RunMain); any other exception exits with 1.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

namespace error_internal {

// Writes "[fatal] <file>:<line>: PROBELESS_DEMAND(<condition>) failed: <message>" to stderr and
// aborts. Out of line of the check itself so that the passing path stays one compare and branch.
[[noreturn, gnu::cold, gnu::noinline]] inline void DemandFailed(const char* file, int line,
                                                                const char* condition,
                                                                const char* message) {
  std::fprintf(stderr, "[fatal] %s:%d: PROBELESS_DEMAND(%s) failed: %s\n", file, line, condition,
               message);
  std::fflush(stderr);
  std::abort();
}

}  // namespace error_internal
}  // namespace probeless

// Checks an invariant of our own code in every build type (unlike assert, which NDEBUG removes
// from the Release and RelWithDebInfo builds tools/test makes). `message` is a string literal
// saying what broke. A failure aborts: a broken invariant in shared memory must not run on.
#define PROBELESS_DEMAND(condition, message)                                              \
  do {                                                                                    \
    if (!(condition)) [[unlikely]]                                                        \
      ::probeless::error_internal::DemandFailed(__FILE__, __LINE__, #condition, message); \
  } while (false)
