// CdrWriter / CdrReader: exact bytes, alignment rules, round trips and error messages.
#include "probeless/log/cdr.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "probeless/testing/expect.h"

namespace probeless::log {
namespace {

using ::testing::ElementsAreArray;

std::vector<uint8_t> AsInts(std::span<const std::byte> bytes) {
  std::vector<uint8_t> out;
  for (std::byte b : bytes) out.push_back(static_cast<uint8_t>(b));
  return out;
}

std::vector<std::byte> AsBytes(const std::vector<uint8_t>& ints) {
  std::vector<std::byte> out;
  for (uint8_t v : ints) out.push_back(std::byte{v});
  return out;
}

TEST(CdrWriterTest, EncapsulationHeaderIsLittleEndianXcdr1) {
  CdrWriter writer;
  EXPECT_THAT(AsInts(writer.data()),
              ElementsAreArray(std::vector<uint8_t>{0x00, 0x01, 0x00, 0x00}));
}

TEST(CdrWriterTest, PrimitivesAlignToTheirSizeFromTheBodyStart) {
  CdrWriter writer;
  writer.Write<uint8_t>(0xAA);         // body offset 0
  writer.Write<uint16_t>(0x0102);      // pad 1 -> offset 2
  writer.Write<uint8_t>(0xBB);         // offset 4
  writer.Write<uint32_t>(0x03040506);  // pad 3 -> offset 8
  writer.Write<uint8_t>(0xCC);         // offset 12
  writer.Write<double>(1.0);           // pad 3 -> offset 16
  writer.Bool(true);                   // offset 24
  writer.Write<int64_t>(-2);           // pad 7 -> offset 32
  EXPECT_THAT(AsInts(writer.data()),
              ElementsAreArray(std::vector<uint8_t>{
                  0x00, 0x01, 0x00, 0x00,                             // header
                  0xAA, 0x00, 0x02, 0x01,                             // u8 pad u16
                  0xBB, 0x00, 0x00, 0x00, 0x06, 0x05, 0x04, 0x03,     // u8 pad u32
                  0xCC, 0x00, 0x00, 0x00,                             // u8 pad
                  0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF0, 0x3F,     // 1.0
                  0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,     // bool pad
                  0xFE, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF}));  // -2
}

TEST(CdrWriterTest, StringsCountTheirNulAndSequencesTheirElements) {
  CdrWriter writer;
  writer.String("ab");                                    // 4 + 3 bytes -> offset 7
  writer.Write<double>(0.5);                              // pad 1 -> offset 8
  writer.Sequence(std::span<const uint16_t>({7, 8, 9}));  // offset 16: count, 3 x u16
  writer.Sequence(std::span<const double>({2.0}));        // offset 26: pad 2, count, 2.0 at 32
  writer.String("");                                      // empty string: length 1, NUL
  EXPECT_THAT(AsInts(writer.data()),
              ElementsAreArray(std::vector<uint8_t>{
                  0x00, 0x01, 0x00, 0x00, 0x03, 0x00, 0x00, 0x00, 'a', 'b', 0x00,  // "ab"
                  0x00,                                                            // pad
                  0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xE0, 0x3F,                  // 0.5
                  0x03, 0x00, 0x00, 0x00, 0x07, 0x00, 0x08, 0x00,                  // u16[3]
                  0x09, 0x00, 0x00, 0x00,                                          // .. pad 2
                  0x01, 0x00, 0x00, 0x00,                                          // count 1
                  0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x40,                  // 2.0
                  0x01, 0x00, 0x00, 0x00, 0x00}));                                 // ""
}

TEST(CdrWriterTest, StdMsgsHeaderMatchesTheRos2WireFormat) {
  // builtin_interfaces/Time {sec 1, nanosec 2}, frame_id "map": the bytes rclcpp produces.
  CdrWriter writer;
  writer.Write<int32_t>(1);
  writer.Write<uint32_t>(2);
  writer.String("map");
  EXPECT_THAT(AsInts(writer.data()),
              ElementsAreArray(std::vector<uint8_t>{0x00, 0x01, 0x00, 0x00, 0x01, 0x00, 0x00,
                                                    0x00, 0x02, 0x00, 0x00, 0x00, 0x04, 0x00,
                                                    0x00, 0x00, 'm',  'a',  'p',  0x00}));
}

TEST(CdrRoundTripTest, EveryTypeComesBack) {
  CdrWriter writer;
  writer.Write<int8_t>(-5);
  writer.Write<int16_t>(-300);
  writer.Write<uint64_t>(std::numeric_limits<uint64_t>::max());
  writer.String("probeless");
  writer.Write<float>(1.5f);
  writer.Bool(false);
  writer.Write<int32_t>(std::numeric_limits<int32_t>::min());
  const double fixed[3] = {0.25, -1e300, std::numeric_limits<double>::infinity()};
  writer.Array(std::span<const double>(fixed));
  writer.Sequence(std::span<const float>({1.0f, -2.0f}));
  const std::byte raw[5] = {std::byte{1}, std::byte{2}, std::byte{3}, std::byte{4}, std::byte{5}};
  writer.ByteSequence(raw);
  writer.Write<uint16_t>(0xBEEF);  // aligned after the odd-length byte sequence
  const std::vector<std::byte> bytes = writer.Take();
  EXPECT_EQ(writer.size(), 4u);  // Take() resets

  CdrReader reader(bytes, "test/Type");
  EXPECT_EQ(reader.Read<int8_t>("a"), -5);
  EXPECT_EQ(reader.Read<int16_t>("b"), -300);
  EXPECT_EQ(reader.Read<uint64_t>("c"), std::numeric_limits<uint64_t>::max());
  EXPECT_EQ(reader.String("d"), "probeless");
  EXPECT_EQ(reader.Read<float>("e"), 1.5f);
  EXPECT_FALSE(reader.Bool("f"));
  EXPECT_EQ(reader.Read<int32_t>("g"), std::numeric_limits<int32_t>::min());
  double got[3];
  reader.Array(std::span<double>(got), "h");
  EXPECT_EQ(got[0], 0.25);
  EXPECT_EQ(got[1], -1e300);
  EXPECT_TRUE(std::isinf(got[2]));
  EXPECT_EQ(reader.Sequence<float>("i"), (std::vector<float>{1.0f, -2.0f}));
  const auto view = reader.SequenceBytes<uint8_t>("j");
  EXPECT_THAT(AsInts(view), ElementsAreArray(std::vector<uint8_t>{1, 2, 3, 4, 5}));
  EXPECT_EQ(reader.Read<uint16_t>("k"), 0xBEEF);
  EXPECT_EQ(reader.remaining(), 0u);
}

TEST(CdrReaderTest, RejectsOtherEncapsulations) {
  PROBELESS_EXPECT_THROWS_MESSAGE(
      CdrReader(AsBytes({0x00, 0x00, 0x00, 0x00}), "pkg/T"), CdrError,
      "CDR pkg/T: encapsulation 0x0000 (big-endian CDR) is not supported");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      CdrReader(AsBytes({0x00, 0x07, 0x00, 0x00}), "pkg/T"), CdrError,
      "CDR pkg/T: encapsulation 0x0007 is not supported (expected 0x0001, little-endian "
      "XCDR1)");
  PROBELESS_EXPECT_THROWS_MESSAGE(CdrReader(AsBytes({0x00, 0x01}), "pkg/T"), CdrError,
                                  "CDR pkg/T: 2 bytes are too few for the encapsulation header");
}

TEST(CdrReaderTest, OutOfBoundsAndMalformedFieldsNameFieldAndOffset) {
  const std::vector<std::byte> short_u64 = AsBytes({0x00, 0x01, 0x00, 0x00, 1, 2, 3});
  PROBELESS_EXPECT_THROWS_MESSAGE(
      {
        CdrReader reader(short_u64, "pkg/T");
        reader.Read<uint64_t>("stamp");
      },
      CdrError, "CDR pkg/T: field 'stamp' at offset 4: 8 bytes needed, only 3 left");

  // The padding itself runs past the end.
  const std::vector<std::byte> padding = AsBytes({0x00, 0x01, 0x00, 0x00, 1, 2});
  PROBELESS_EXPECT_THROWS_MESSAGE(
      {
        CdrReader reader(padding, "pkg/T");
        reader.Read<uint8_t>("a");
        reader.Read<uint64_t>("b");
      },
      CdrError,
      "CDR pkg/T: field 'b' at offset 6: alignment padding runs past the end of the "
      "6-byte buffer");

  const std::vector<std::byte> huge_sequence =
      AsBytes({0x00, 0x01, 0x00, 0x00, 0xFF, 0xFF, 0xFF, 0xFF, 1, 2, 3, 4});
  PROBELESS_EXPECT_THROWS_MESSAGE(
      {
        CdrReader reader(huge_sequence, "pkg/T");
        reader.Sequence<double>("d");
      },
      CdrError, "CDR pkg/T: field 'd' at offset 12: 34359738360 bytes needed, only 0 left");

  const std::vector<std::byte> no_nul =
      AsBytes({0x00, 0x01, 0x00, 0x00, 0x02, 0x00, 0x00, 0x00, 'a', 'b'});
  PROBELESS_EXPECT_THROWS_MESSAGE(
      {
        CdrReader reader(no_nul, "pkg/T");
        reader.String("frame_id");
      },
      CdrError, "CDR pkg/T: field 'frame_id' at offset 8: string does not end in NUL");

  const std::vector<std::byte> zero_length =
      AsBytes({0x00, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00});
  PROBELESS_EXPECT_THROWS_MESSAGE(
      {
        CdrReader reader(zero_length, "pkg/T");
        reader.String("s");
      },
      CdrError,
      "CDR pkg/T: field 's' at offset 8: string length 0 (must count the terminating NUL)");

  const std::vector<std::byte> long_string =
      AsBytes({0x00, 0x01, 0x00, 0x00, 0x10, 0x00, 0x00, 0x00, 'a', 0});
  PROBELESS_EXPECT_THROWS_MESSAGE(
      {
        CdrReader reader(long_string, "pkg/T");
        reader.String("s");
      },
      CdrError, "CDR pkg/T: field 's' at offset 8: 16 bytes needed, only 2 left");

  const std::vector<std::byte> bad_bool = AsBytes({0x00, 0x01, 0x00, 0x00, 0x02});
  PROBELESS_EXPECT_THROWS_MESSAGE(
      {
        CdrReader reader(bad_bool, "pkg/T");
        reader.Bool("flag");
      },
      CdrError, "CDR pkg/T: field 'flag' at offset 5: bool byte 2 is neither 0 nor 1");
}

}  // namespace
}  // namespace probeless::log
