// The number parser's rules and its exact messages (tools' tests assert them through their CLIs).
#include <gtest/gtest.h>

#include <cstdint>
#include <string>

#include "probeless/parse/number.h"
#include "probeless/testing/expect.h"

namespace probeless::parse {
namespace {

TEST(ParseInteger, AcceptsWholeDecimalIntegers) {
  EXPECT_EQ(ParseInteger<int>("--n", "12"), 12);
  EXPECT_EQ(ParseInteger<int>("--n", "+12"), 12);
  EXPECT_EQ(ParseInteger<int>("--n", "-12"), -12);
  EXPECT_EQ(ParseInteger<int>("--n", "0007"), 7);
  EXPECT_EQ(ParseInteger<uint64_t>("--n", "18446744073709551615"), UINT64_MAX);
  EXPECT_EQ(ParseInteger<int64_t>("--n", "-9223372036854775808"), INT64_MIN);
  EXPECT_EQ(ParseInteger<uint8_t>("--n", "255"), 255);
}

TEST(ParseInteger, RejectsPartialAndMalformedText) {
  for (const char* bad : {"12abc", "abc", "", " 12", "12 ", "1.5", "1e3", "0x10", "+", "-", "+-1",
                          "++1", "--1", "1-"}) {
    EXPECT_FALSE(TryParseInteger<int>(bad)) << bad;
    EXPECT_FALSE(TryParseInteger<uint64_t>(bad)) << bad;
  }
}

TEST(ParseInteger, MessagesNameTheInputAndTheExpectation) {
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseInteger<uint64_t>("--max-frames", "12abc"), NumberError,
                                  "--max-frames expects a non-negative integer, got '12abc'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseInteger<uint64_t>("--chunk-size", "-1", 1), NumberError,
                                  "--chunk-size expects a positive integer, got '-1'");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ParseInteger<uint64_t>("--chunk-size", "99999999999999999999", 1), NumberError,
      "--chunk-size expects a positive integer up to 18446744073709551615, got "
      "'99999999999999999999'");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ParseInteger<int>("device", "99999999999999999999", 0), NumberError,
      "device expects a non-negative integer up to 2147483647, got '99999999999999999999'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseInteger<int>("--x", "-99999999999"), NumberError,
                                  "--x expects an integer down to -2147483648, got '-99999999999'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseInteger<int>("--x", "4 2"), NumberError,
                                  "--x expects an integer, got '4 2'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseInteger<int>("--level", "7", 0, 3), NumberError,
                                  "--level expects an integer in [0, 3], got '7'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseInteger<uint16_t>("--port", "70000", 1), NumberError,
                                  "--port expects a positive integer up to 65535, got '70000'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseInteger<int>("--n", "0", 1), NumberError,
                                  "--n expects a positive integer, got '0'");
  // A newline from a file stays on the message's one line.
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseInteger<int>("count", "3\n"), NumberError,
                                  "count expects an integer, got '3\\x0a'");
}

TEST(ParseDouble, AcceptsFixedAndScientific) {
  EXPECT_DOUBLE_EQ(ParseDouble("--fps", "30"), 30);
  EXPECT_DOUBLE_EQ(ParseDouble("--fps", "+2.5"), 2.5);
  EXPECT_DOUBLE_EQ(ParseDouble("--fps", "-2e-3"), -2e-3);
  EXPECT_DOUBLE_EQ(ParseDouble("--fps", ".5"), 0.5);
  EXPECT_DOUBLE_EQ(ParseDouble("--fps", "5."), 5);
  EXPECT_GT(ParseDouble("--fps", "1e-310"), 0);  // a denormal is a value
}

TEST(ParseDouble, RejectsPartialNonFiniteAndOutOfRange) {
  for (const char* bad : {"12abc", "", " 1", "1 ", "inf", "-inf", "nan", "infinity", "0x10", "1e",
                          "1e+", "1e400", "-1e400", "1e-400", "+-1", "1,5", "."}) {
    EXPECT_FALSE(TryParseDouble(bad)) << bad;
  }
  EXPECT_FALSE(TryParseDouble("2", 0, 1));
  EXPECT_TRUE(TryParseDouble("1", 0, 1));
}

TEST(ParseDouble, Messages) {
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseDouble("--fps", "30fps"), NumberError,
                                  "--fps expects a number, got '30fps'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseDouble("--gain", "-1", 0), NumberError,
                                  "--gain expects a non-negative number, got '-1'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseDouble("--gain", "0.1", 0.5), NumberError,
                                  "--gain expects a number >= 0.5, got '0.1'");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ParseDouble("--gain", "3", std::numeric_limits<double>::lowest(), 2), NumberError,
      "--gain expects a number <= 2, got '3'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseDouble("albedo", "1.5", 0, 1), NumberError,
                                  "albedo expects a number in [0, 1], got '1.5'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParsePositiveDouble("--fps", "0"), NumberError,
                                  "--fps expects a positive number, got '0'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParsePositiveDouble("--fps", "nan"), NumberError,
                                  "--fps expects a positive number, got 'nan'");
}

TEST(ParseFloat, RangeOfFloat) {
  EXPECT_FLOAT_EQ(ParseFloat("--scale", "0.25"), 0.25f);
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseFloat("--scale", "1e39"), NumberError,
                                  "--scale expects a number, got '1e39'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseFloat("--scale", "2", 0, 1), NumberError,
                                  "--scale expects a number in [0, 1], got '2'");
}

TEST(ParseList, CountAndItems) {
  EXPECT_EQ(ParseDoubleList("--origin", "1,-2.5,3", 3, 3), (std::vector<double>{1, -2.5, 3}));
  EXPECT_EQ(ParseIntegerList<int>("--icp", "10,5", 1, 3, 1), (std::vector<int>{10, 5}));
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseDoubleList("--origin", "1,2", 3, 3), NumberError,
                                  "--origin expects 3 comma-separated numbers, got '1,2'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseDoubleList("--origin", "1,2,3,", 3, 3), NumberError,
                                  "--origin expects 3 comma-separated numbers, got '1,2,3,'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseIntegerList<int>("--k", "", 1, 2), NumberError,
                                  "--k item 1 expects an integer, got ''");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseDoubleList("--origin", "1,y,3", 3, 3), NumberError,
                                  "--origin item 2 expects a number, got 'y'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseIntegerList<int>("FUSION_EVAL_ICP", "10,5,-4", 3, 3, 1),
                                  NumberError,
                                  "FUSION_EVAL_ICP item 3 expects a positive integer, got '-4'");
  PROBELESS_EXPECT_THROWS_MESSAGE(ParseIntegerList<int>("--k", "1,2,3", 1, 2), NumberError,
                                  "--k expects 1 to 2 comma-separated numbers, got '1,2,3'");
}

TEST(NumberError, IsInvalidArgument) {
  // node::RunMain maps InputError to exit code 2; tools rely on that.
  EXPECT_THROW(ParseInteger<int>("--n", "x"), InputError);
}

}  // namespace
}  // namespace probeless::parse
