// The shared `main` of node and tool processes: one error policy for every executable.
//
//   int main(int argc, char** argv) {
//     return probeless::node::RunMain<dataset::DatasetError>("player", [&] { return Run(argc,
//     argv); });
//   }
//
// Exit codes: whatever the body returns; 2 for bad input — UsageError, NodeError,
// std::invalid_argument and the BadInput types listed (e.g. a library's file-format error); 1 for
// any other exception. Each failure is one line on stderr: "[error] [<name>] <what>".
#pragma once

#include <cstdio>
#include <exception>
#include <stdexcept>
#include <string>
#include <string_view>

#include "probeless/node/node.h"

namespace probeless::node {

// A malformed command line (unknown option, missing or non-numeric value): exit code 2.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// `text` as a finite number (parse::TryParseDouble's rules); throws UsageError
// "<option> expects a number, got '<text>'". Integer options use parse::ParseInteger (its
// NumberError is an invalid_argument: exit 2 through RunMain too).
double ParseNumberOption(std::string_view option, std::string_view text);

template <class... BadInput, class Body>
int RunMain(std::string_view name, Body&& body) {
  auto fail = [&](const std::exception& e, int code) {
    std::fprintf(stderr, "[error] [%.*s] %s\n", static_cast<int>(name.size()), name.data(),
                 e.what());
    return code;
  };
  try {
    return body();
  } catch (const UsageError& e) {
    return fail(e, 2);
  } catch (const NodeError& e) {
    return fail(e, 2);
  } catch (const std::invalid_argument& e) {
    return fail(e, 2);
  } catch (const std::exception& e) {
    const bool bad_input = (... || (dynamic_cast<const BadInput*>(&e) != nullptr));
    return fail(e, bad_input ? 2 : 1);
  }
}

}  // namespace probeless::node
