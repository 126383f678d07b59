// Assertions on thrown exceptions shared by the probeless tests (target probeless_testing,
// header-only, tests only): the message of the exception a callable throws, and gtest-style
// expectations that a statement throws a given type with a given message. They replace the
// ErrorOf/MessageOf helper each test file used to define (issue #21).
//
//   PROBELESS_EXPECT_THROWS_MESSAGE(ParseInteger<uint64_t>("--max-frames", "12abc"), NumberError,
//                                   "--max-frames expects a non-negative integer, got '12abc'");
//   PROBELESS_EXPECT_THROWS_MESSAGE_THAT(Decode(bytes), CdrError, HasSubstr("offset 12"));
//   EXPECT_EQ(probeless::testing::ThrownMessage<NodeError>([&] { Node node(argv, "t"); }), "...");
#pragma once

#include <cxxabi.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <exception>
#include <functional>
#include <memory>
#include <sstream>
#include <string>
#include <type_traits>
#include <typeinfo>

namespace probeless::testing {

// What ThrownMessage returns when the action returns normally: not a message any code under test
// writes, so an EXPECT_EQ against the expected message fails showing it.
inline constexpr const char* kNoException = "(no error)";

// Runs `action` and returns e.what() of the exception of type `Exception` (or derived) it throws,
// kNoException if it returns normally. Any other exception, std or not, propagates (the test fails
// on it as on an unexpected throw): with the default std::exception only non-std ones do.
template <class Exception = std::exception>
std::string ThrownMessage(const std::function<void()>& action) {
  static_assert(std::is_base_of_v<std::exception, Exception>, "Exception must be a std::exception");
  try {
    action();
  } catch (const Exception& e) {
    return e.what();
  }
  return kNoException;
}

namespace expect_internal {

// The readable (demangled) name of a type from its typeid, the mangled name if demangling fails.
inline std::string TypeName(const std::type_info& type) {
  int status = 0;
  const std::unique_ptr<char, void (*)(void*)> name(
      abi::__cxa_demangle(type.name(), nullptr, nullptr, &status), std::free);
  return status == 0 && name ? name.get() : type.name();
}

// What a statement threw, as the expectations compare and report it.
struct Outcome {
  enum class Kind { kNothing, kExpected, kOtherStd, kNonStd } kind = Kind::kNothing;
  std::string type;     // dynamic type of the exception (kExpected, kOtherStd)
  std::string message;  // its what() (kExpected, kOtherStd)
};

// Runs `statement` and classifies what it throws: `Exception` (or derived), another
// std::exception, a non-std exception, or nothing. Never throws itself.
template <class Exception>
Outcome Run(const std::function<void()>& statement) {
  static_assert(std::is_base_of_v<std::exception, Exception>, "Exception must be a std::exception");
  Outcome outcome;
  try {
    // Nested so that Exception = std::exception does not shadow the handler below.
    try {
      statement();
    } catch (const Exception& e) {
      outcome = {Outcome::Kind::kExpected, TypeName(typeid(e)), e.what()};
    }
  } catch (const std::exception& e) {
    outcome = {Outcome::Kind::kOtherStd, TypeName(typeid(e)), e.what()};
  } catch (...) {
    outcome.kind = Outcome::Kind::kNonStd;
  }
  return outcome;
}

// "throws nothing", "throws <type> with message "<what>"" or "throws a non-std exception".
inline std::string Describe(const Outcome& outcome) {
  switch (outcome.kind) {
    case Outcome::Kind::kNothing:
      return "throws nothing";
    case Outcome::Kind::kNonStd:
      return "throws an exception not derived from std::exception";
    default:
      return "throws " + outcome.type + " with message " +
             ::testing::PrintToString(outcome.message);
  }
}

// Success iff `statement` throws `Exception` with what() == `expected`; else the failure text
// names the statement, the expected type and message and what it did instead.
template <class Exception>
::testing::AssertionResult ThrowsMessage(const std::function<void()>& statement,
                                         const char* statement_text, const char* type_text,
                                         const std::string& expected) {
  const Outcome outcome = Run<Exception>(statement);
  if (outcome.kind == Outcome::Kind::kExpected && outcome.message == expected) {
    return ::testing::AssertionSuccess();
  }
  return ::testing::AssertionFailure()
         << "Expected: " << statement_text << " throws " << type_text << " with message "
         << ::testing::PrintToString(expected) << "\n  Actual: it " << Describe(outcome);
}

// Success iff `statement` throws `Exception` whose what() matches `matcher` (a gmock matcher of
// std::string, or a string for equality); else the failure text says what it did instead.
template <class Exception, class M>
::testing::AssertionResult ThrowsMessageThat(const std::function<void()>& statement,
                                             const char* statement_text, const char* type_text,
                                             const M& matcher) {
  const ::testing::Matcher<const std::string&> message_matcher =
      ::testing::MatcherCast<const std::string&>(matcher);
  const Outcome outcome = Run<Exception>(statement);
  ::testing::StringMatchResultListener explanation;
  if (outcome.kind == Outcome::Kind::kExpected &&
      message_matcher.MatchAndExplain(outcome.message, &explanation)) {
    return ::testing::AssertionSuccess();
  }
  std::ostringstream description;
  message_matcher.DescribeTo(&description);
  ::testing::AssertionResult failure = ::testing::AssertionFailure();
  failure << "Expected: " << statement_text << " throws " << type_text << " whose message "
          << description.str() << "\n  Actual: it " << Describe(outcome);
  if (!explanation.str().empty()) failure << ", " << explanation.str();
  return failure;
}

}  // namespace expect_internal
}  // namespace probeless::testing

// A non-fatal gtest failure unless `statement` throws `ExceptionType` (or a type derived from it)
// whose what() equals `expected_message` exactly. The failure names the statement, the expected
// type and message, and what was thrown instead (another type, another message, nothing). Behaves
// like EXPECT_THROW: one statement, safe in an unbraced if/else, takes `<< extra` context. A
// top-level comma in `statement` needs parentheses, as with every gtest macro.
#define PROBELESS_EXPECT_THROWS_MESSAGE(statement, ExceptionType, expected_message) \
  PROBELESS_EXPECT_THROWS_INTERNAL_(                                                \
      ::probeless::testing::expect_internal::ThrowsMessage<ExceptionType>(          \
          [&] { statement; }, #statement, #ExceptionType, expected_message))

// As PROBELESS_EXPECT_THROWS_MESSAGE, but the what() must match the gmock matcher `matcher`
// (HasSubstr, StartsWith, MatchesRegex, ...); the failure shows the matcher's description.
#define PROBELESS_EXPECT_THROWS_MESSAGE_THAT(statement, ExceptionType, matcher) \
  PROBELESS_EXPECT_THROWS_INTERNAL_(                                            \
      ::probeless::testing::expect_internal::ThrowsMessageThat<ExceptionType>(  \
          [&] { statement; }, #statement, #ExceptionType, matcher))

// gtest's own shape (GTEST_ASSERT_): the switch keeps a following `else` from binding to our if.
#define PROBELESS_EXPECT_THROWS_INTERNAL_(assertion)                          \
  switch (0)                                                                  \
  case 0:                                                                     \
  default:                                                                    \
    if (const ::testing::AssertionResult probeless_expect_result = assertion) \
      ;                                                                       \
    else                                                                      \
      ADD_FAILURE() << probeless_expect_result.message()
