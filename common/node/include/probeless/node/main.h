// The shared `main` of node and tool processes: one error policy for every executable.
//
//   int main(int argc, char** argv) {
//     return probeless::node::RunMain("player", [&] { return Run(argc, argv); });
//   }
//
// Exit codes: whatever the body returns; 2 for bad input — every InputError (UsageError,
// NodeError, each library's boundary error: probeless/error/error.h) and std::invalid_argument
// from the standard library; 1 for any other exception (a bug or a system failure). Each failure
// is one line on stderr: "[error] [<name>] <what>".
#pragma once

#include <cstdio>
#include <exception>
#include <stdexcept>
#include <string>
#include <string_view>

#include "probeless/error/error.h"
#include "probeless/node/node.h"

namespace probeless::node {

// A malformed command line (unknown option, missing or non-numeric value): exit code 2.
class UsageError : public InputError {
 public:
  using InputError::InputError;
};

// `text` as a finite number (parse::TryParseDouble's rules); throws UsageError
// "<option> expects a number, got '<text>'". Integer options use parse::ParseInteger (its
// NumberError is an InputError: exit 2 through RunMain too).
double ParseNumberOption(std::string_view option, std::string_view text);

template <class Body>
int RunMain(std::string_view name, Body&& body) {
  auto fail = [&](const std::exception& e, int code) {
    std::fprintf(stderr, "[error] [%.*s] %s\n", static_cast<int>(name.size()), name.data(),
                 e.what());
    return code;
  };
  try {
    return body();
  } catch (const InputError& e) {
    return fail(e, 2);
  } catch (const std::invalid_argument& e) {
    return fail(e, 2);
  } catch (const std::exception& e) {
    return fail(e, 1);
  }
}

}  // namespace probeless::node
