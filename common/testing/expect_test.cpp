// Tests of probeless/testing/expect.h: ThrownMessage and the PROBELESS_EXPECT_THROWS_MESSAGE(_THAT)
// expectations pass on the expected throw and fail, saying what happened, on anything else.
#include "probeless/testing/expect.h"

#include <gmock/gmock.h>
#include <gtest/gtest-spi.h>
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

namespace probeless::testing {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;

// The shape of the libraries' error classes: a base type and a subclass of it.
class BaseError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
class DerivedError : public BaseError {
 public:
  using BaseError::BaseError;
};

[[noreturn]] void ThrowBase(const char* message) { throw BaseError(message); }
[[noreturn]] void ThrowDerived(const char* message) { throw DerivedError(message); }
[[noreturn]] void ThrowLogic(const char* message) { throw std::logic_error(message); }
[[noreturn]] void ThrowInt() { throw 7; }
void DoNothing() {}

TEST(ThrownMessage, ReturnsTheWhatOfTheThrownException) {
  EXPECT_EQ(ThrownMessage([] { ThrowBase("bad input"); }), "bad input");
  EXPECT_EQ(ThrownMessage([] { ThrowLogic("broken"); }), "broken");
}

TEST(ThrownMessage, ReturnsTheSentinelWhenNothingIsThrown) {
  EXPECT_EQ(ThrownMessage(DoNothing), kNoException);
  EXPECT_EQ(std::string(kNoException), "(no error)");
}

TEST(ThrownMessage, RethrowsANonStdException) { EXPECT_THROW(ThrownMessage(ThrowInt), int); }

TEST(ThrownMessage, WithATypeCatchesItAndItsSubclassesOnly) {
  EXPECT_EQ(ThrownMessage<BaseError>([] { ThrowDerived("derived"); }), "derived");
  EXPECT_THROW(ThrownMessage<DerivedError>([] { ThrowBase("base"); }), BaseError);
  EXPECT_THROW(ThrownMessage<BaseError>([] { ThrowLogic("logic"); }), std::logic_error);
}

TEST(ExpectThrowsMessage, PassesOnTheTypeAndTheExactMessage) {
  PROBELESS_EXPECT_THROWS_MESSAGE(ThrowBase("bad input"), BaseError, "bad input");
  const std::string expected = "bad input";
  PROBELESS_EXPECT_THROWS_MESSAGE(ThrowBase("bad input"), BaseError, expected);
}

TEST(ExpectThrowsMessage, PassesOnASubclassOfTheType) {
  PROBELESS_EXPECT_THROWS_MESSAGE(ThrowDerived("x"), BaseError, "x");
  PROBELESS_EXPECT_THROWS_MESSAGE(ThrowDerived("x"), std::exception, "x");
}

TEST(ExpectThrowsMessage, RunsTheStatementOnceWithLocalsAndDeclarations) {
  int runs = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      {
        ++runs;
        ThrowBase("once");
      },
      BaseError, "once");
  EXPECT_EQ(runs, 1);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      {
        std::string s(2, 'x');
        ThrowBase(s.c_str());
      },
      BaseError, "xx");
}

TEST(ExpectThrowsMessage, FailsOnAnotherMessageShowingBoth) {
  EXPECT_NONFATAL_FAILURE(
      PROBELESS_EXPECT_THROWS_MESSAGE(ThrowBase("got"), BaseError, "wanted"),
      "Expected: ThrowBase(\"got\") throws BaseError with message \"wanted\"\n"
      "  Actual: it throws probeless::testing::(anonymous namespace)::BaseError "
      "with message \"got\"");
  // A prefix is not the message.
  EXPECT_NONFATAL_FAILURE(PROBELESS_EXPECT_THROWS_MESSAGE(ThrowBase("abc"), BaseError, "ab"),
                          "with message \"abc\"");
}

TEST(ExpectThrowsMessage, FailsOnAnotherExceptionTypeNamingIt) {
  EXPECT_NONFATAL_FAILURE(PROBELESS_EXPECT_THROWS_MESSAGE(ThrowLogic("m"), BaseError, "m"),
                          "Actual: it throws std::logic_error with message \"m\"");
  // A base of the expected type is another type.
  EXPECT_NONFATAL_FAILURE(PROBELESS_EXPECT_THROWS_MESSAGE(ThrowBase("m"), DerivedError, "m"),
                          "::BaseError with message \"m\"");
  EXPECT_NONFATAL_FAILURE(PROBELESS_EXPECT_THROWS_MESSAGE(ThrowInt(), BaseError, "m"),
                          "Actual: it throws an exception not derived from std::exception");
}

TEST(ExpectThrowsMessage, FailsWhenNothingIsThrown) {
  EXPECT_NONFATAL_FAILURE(PROBELESS_EXPECT_THROWS_MESSAGE(DoNothing(), BaseError, "m"),
                          "Expected: DoNothing() throws BaseError with message \"m\"\n"
                          "  Actual: it throws nothing");
}

TEST(ExpectThrowsMessage, IsOneStatementInAnUnbracedIfElseAndTakesStreamedContext) {
  bool took_else = false;
  if (took_else)
    PROBELESS_EXPECT_THROWS_MESSAGE(DoNothing(), BaseError, "never checked");
  else
    took_else = true;
  EXPECT_TRUE(took_else);
  EXPECT_NONFATAL_FAILURE(PROBELESS_EXPECT_THROWS_MESSAGE(DoNothing(), BaseError, "m") << "case 3",
                          "case 3");
}

TEST(ExpectThrowsMessageThat, PassesWhenTheMessageMatches) {
  PROBELESS_EXPECT_THROWS_MESSAGE_THAT(ThrowBase("file.yaml:3: bad key"), BaseError,
                                       HasSubstr("bad key"));
  PROBELESS_EXPECT_THROWS_MESSAGE_THAT(ThrowDerived("file.yaml:3: bad key"), BaseError,
                                       StartsWith("file.yaml:"));
}

TEST(ExpectThrowsMessageThat, FailsOnAMismatchShowingTheMatcher) {
  EXPECT_NONFATAL_FAILURE(
      PROBELESS_EXPECT_THROWS_MESSAGE_THAT(ThrowBase("abc"), BaseError, HasSubstr("xyz")),
      "Expected: ThrowBase(\"abc\") throws BaseError whose message has substring \"xyz\"\n"
      "  Actual: it throws probeless::testing::(anonymous namespace)::BaseError with message "
      "\"abc\"");
}

TEST(ExpectThrowsMessageThat, FailsOnAnotherTypeOrNothing) {
  EXPECT_NONFATAL_FAILURE(
      PROBELESS_EXPECT_THROWS_MESSAGE_THAT(ThrowLogic("abc"), BaseError, HasSubstr("abc")),
      "Actual: it throws std::logic_error with message \"abc\"");
  EXPECT_NONFATAL_FAILURE(
      PROBELESS_EXPECT_THROWS_MESSAGE_THAT(DoNothing(), BaseError, HasSubstr("abc")),
      "Actual: it throws nothing");
}

}  // namespace
}  // namespace probeless::testing
