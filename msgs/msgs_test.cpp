// Unit tests of the message layouts, layout hashes, size helpers and accessors.
#include "probeless/msgs/msgs.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "probeless/testing/expect.h"

namespace probeless::msgs {
namespace {

// A 64-byte aligned byte buffer, like a bus slot.
class Slot {
 public:
  explicit Slot(size_t bytes, std::byte fill = std::byte{0xAB})
      : data_(static_cast<std::byte*>(std::aligned_alloc(64, (bytes + 63) / 64 * 64 + 64))),
        size_(bytes) {
    std::memset(data_.get(), static_cast<int>(fill), size_);
  }
  std::span<std::byte> bytes() { return {data_.get(), size_}; }
  std::span<const std::byte> cbytes() const { return {data_.get(), size_}; }

 private:
  struct Free {
    void operator()(std::byte* p) const { std::free(p); }
  };
  std::unique_ptr<std::byte, Free> data_;
  size_t size_;
};

// --- Layout hash -------------------------------------------------------------------------------

TEST(LayoutHashTest, Fnv1a64MatchesReferenceVectors) {
  static_assert(layout::Fnv1a64("") == 0xcbf29ce484222325ull);
  EXPECT_EQ(layout::Fnv1a64(""), 0xcbf29ce484222325ull);
  EXPECT_EQ(layout::Fnv1a64("a"), 0xaf63dc4c8601ec8cull);
  EXPECT_EQ(layout::Fnv1a64("foobar"), 0x85944171f73967e8ull);
}

TEST(LayoutHashTest, DescriptionsDifferingInOneFieldHashDifferently) {
  const std::string base = "t/M{a:u32@0;b:u32@4;}size=8,align=4";
  const std::vector<std::string> variants = {
      "t/M{a:u32@0;b:f32@4;}size=8,align=4",   // type changed
      "t/M{a:u32@0;c:u32@4;}size=8,align=4",   // name changed
      "t/M{a:u32@0;b:u32@8;}size=12,align=4",  // offset and size changed
      "t/N{a:u32@0;b:u32@4;}size=8,align=4",   // type name changed
  };
  std::set<uint64_t> hashes = {layout::Fnv1a64(base)};
  for (const std::string& v : variants) hashes.insert(layout::Fnv1a64(v));
  EXPECT_EQ(hashes.size(), variants.size() + 1);
}

// A received frame_id is any bytes; the one-line errors that quote it escape it.
TEST(FixedStringTest, PrintableTextEscapesWhatWouldBreakALine) {
  EXPECT_EQ(PrintableText("camera_rgb"), "camera_rgb");
  EXPECT_EQ(PrintableText(std::string_view("a\nb\\c\x7f\xff\0", 8)),
            "a\\x0ab\\x5cc\\x7f\\xff\\x00");
  CameraInfo info{};
  std::memcpy(info.header.frame_id, "cam\nera", 8);
  info.distortion_model = static_cast<DistortionModel>(9);
  PROBELESS_EXPECT_THROWS_MESSAGE(info.Validate(), MessageError,
                                  "probeless_msgs/CameraInfo 'cam\\x0aera': invalid distortion "
                                  "model 9");
}

TEST(LayoutHashTest, DecimalFormatsNumbers) {
  EXPECT_EQ(layout::Decimal(0), "0");
  EXPECT_EQ(layout::Decimal(921600), "921600");
  EXPECT_EQ(layout::Decimal(18446744073709551615ull), "18446744073709551615");
}

struct V1 {
  uint32_t a;
  uint32_t b;
  static constexpr std::string_view kTypeName = "test/V";
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder builder(kTypeName);
    PROBELESS_MSGS_FIELD(builder, V1, a);
    PROBELESS_MSGS_FIELD(builder, V1, b);
    return builder.Finish<V1>();
  }
};
struct V2 {  // b changes type (same size and offset)
  uint32_t a;
  float b;
  static constexpr std::string_view kTypeName = "test/V";
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder builder(kTypeName);
    PROBELESS_MSGS_FIELD(builder, V2, a);
    PROBELESS_MSGS_FIELD(builder, V2, b);
    return builder.Finish<V2>();
  }
};
struct V3 {  // b is renamed
  uint32_t a;
  uint32_t c;
  static constexpr std::string_view kTypeName = "test/V";
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder builder(kTypeName);
    PROBELESS_MSGS_FIELD(builder, V3, a);
    PROBELESS_MSGS_FIELD(builder, V3, c);
    return builder.Finish<V3>();
  }
};
struct V4 {  // a field is appended
  uint32_t a;
  uint32_t b;
  uint32_t extra;
  uint32_t reserved;
  static constexpr std::string_view kTypeName = "test/V";
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder builder(kTypeName);
    PROBELESS_MSGS_FIELD(builder, V4, a);
    PROBELESS_MSGS_FIELD(builder, V4, b);
    PROBELESS_MSGS_FIELD(builder, V4, extra);
    PROBELESS_MSGS_FIELD(builder, V4, reserved);
    return builder.Finish<V4>();
  }
};
template <class Inner>
struct Outer {  // nests Inner: its hash must follow Inner's layout
  uint64_t stamp;
  Inner inner;
  static constexpr std::string_view kTypeName = "test/Outer";
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder builder(kTypeName);
    PROBELESS_MSGS_FIELD(builder, Outer, stamp);
    PROBELESS_MSGS_FIELD(builder, Outer, inner);
    return builder.Finish<Outer>();
  }
};
enum class E1 : uint32_t { kA = 0, kB = 1 };
constexpr std::string_view DescribeEnum(E1) { return "E{a=0,b=1}"; }
enum class E2 : uint32_t { kA = 0, kB = 2 };
constexpr std::string_view DescribeEnum(E2) { return "E{a=0,b=2}"; }
template <class Enum>
struct WithEnum {
  Enum value;
  static constexpr std::string_view kTypeName = "test/WithEnum";
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder builder(kTypeName);
    PROBELESS_MSGS_FIELD(builder, WithEnum, value);
    return builder.Finish<WithEnum>();
  }
};

TEST(LayoutHashTest, ChangingAFieldChangesTheHash) {
  EXPECT_EQ(V1::LayoutDescription(), "test/V{a:u32@0;b:u32@4;}size=8,align=4");
  EXPECT_EQ(V2::LayoutDescription(), "test/V{a:u32@0;b:f32@4;}size=8,align=4");
  constexpr uint64_t h1 = layout::Fnv1a64(V1::LayoutDescription());
  constexpr uint64_t h2 = layout::Fnv1a64(V2::LayoutDescription());
  constexpr uint64_t h3 = layout::Fnv1a64(V3::LayoutDescription());
  constexpr uint64_t h4 = layout::Fnv1a64(V4::LayoutDescription());
  EXPECT_EQ((std::set<uint64_t>{h1, h2, h3, h4}).size(), 4u);

  // A change inside a nested struct changes the outer hash.
  EXPECT_EQ(Outer<V1>::LayoutDescription(),
            "test/Outer{stamp:u64@0;inner:test/V{a:u32@0;b:u32@4;}size=8,align=4@8;}size=16,"
            "align=8");
  EXPECT_NE(layout::Fnv1a64(Outer<V1>::LayoutDescription()),
            layout::Fnv1a64(Outer<V2>::LayoutDescription()));
  // Renumbering an enumerator changes the hash.
  EXPECT_EQ(WithEnum<E1>::LayoutDescription(),
            "test/WithEnum{value:E{a=0,b=1}:u32@0;}size=4,align=4");
  EXPECT_NE(layout::Fnv1a64(WithEnum<E1>::LayoutDescription()),
            layout::Fnv1a64(WithEnum<E2>::LayoutDescription()));
}

struct Holey {
  uint8_t a;
  uint32_t b;  // 3 implicit padding bytes before b
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder builder("test/Holey");
    PROBELESS_MSGS_FIELD(builder, Holey, a);
    PROBELESS_MSGS_FIELD(builder, Holey, b);
    return builder.Finish<Holey>();
  }
};
struct TailPadded {
  uint64_t a;
  uint8_t b;  // 7 implicit tail padding bytes
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder builder("test/TailPadded");
    PROBELESS_MSGS_FIELD(builder, TailPadded, a);
    PROBELESS_MSGS_FIELD(builder, TailPadded, b);
    return builder.Finish<TailPadded>();
  }
};
struct Unlisted {
  uint32_t a;
  uint32_t b;
  uint32_t c;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder builder("test/Unlisted");
    PROBELESS_MSGS_FIELD(builder, Unlisted, a);
    PROBELESS_MSGS_FIELD(builder, Unlisted, c);  // b forgotten
    return builder.Finish<Unlisted>();
  }
};

TEST(LayoutHashTest, BuilderRejectsImplicitPaddingAndUnlistedFields) {
  // In a constant expression (kLayoutHash) these are compile errors; at run time they throw.
  PROBELESS_EXPECT_THROWS_MESSAGE(
      Holey::LayoutDescription(), MessageError,
      "layout of test/Holey: field 'b' at offset 4, expected 1 (implicit padding or a field "
      "missing from the description)");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      TailPadded::LayoutDescription(), MessageError,
      "layout of test/TailPadded: fields end at byte 9 but sizeof is 16 (implicit tail "
      "padding or a field missing from the description)");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      Unlisted::LayoutDescription(), MessageError,
      "layout of test/Unlisted: field 'c' at offset 8, expected 4 (implicit padding or a "
      "field missing from the description)");
}

template <class... M>
void ExpectDistinctSelfConsistentHashes() {
  std::set<uint64_t> hashes;
  std::set<std::string_view> names;
  (
      [&] {
        static_assert(Message<M>);
        static_assert(std::is_trivially_copyable_v<M> && std::is_standard_layout_v<M>);
        EXPECT_EQ(M::kLayoutHash, layout::Fnv1a64(M::LayoutDescription())) << M::kTypeName;
        EXPECT_TRUE(M::LayoutDescription().starts_with(std::string(M::kTypeName) + "{"));
        EXPECT_TRUE(M::LayoutDescription().ends_with("}size=" + std::to_string(sizeof(M)) +
                                                     ",align=" + std::to_string(alignof(M))));
        EXPECT_TRUE(M::kTypeName.starts_with("probeless_msgs/"));
        EXPECT_LE(M::kTypeName.size(), bus::kMaxNameLength);
        hashes.insert(M::kLayoutHash);
        names.insert(M::kTypeName);
      }(),
      ...);
  EXPECT_EQ(hashes.size(), sizeof...(M));
  EXPECT_EQ(names.size(), sizeof...(M));
}

TEST(LayoutHashTest, EveryMessageTypeHasADistinctSelfConsistentHash) {
  ExpectDistinctSelfConsistentHashes<Header, Vector3, Quaternion, RigidTransform, Image, CameraInfo,
                                     Pose, FaceObservation, ShLight, GeometryBuffer, TransferBuffer,
                                     Ack, PlayerControl, AuxiliaryView, AuxiliaryViews,
                                     TrackingStatus>();
}

TEST(TrackingStatusTest, ValidatesStateScoreAndFlags) {
  TrackingStatus status;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      status.Validate(), MessageError,
      "probeless_msgs/TrackingStatus: state 0 is not tracked (1), uncertain (2) or lost (3)");
  status.state = TrackingStatusState::kUncertain;
  status.score = 0.25f;
  EXPECT_NO_THROW(status.Validate());
  status.score = 1.5f;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      status.Validate(), MessageError,
      "probeless_msgs/TrackingStatus: score 1.500000 is outside [0, 1]");
  status.score = 0;
  status.integrated = 2;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      status.Validate(), MessageError,
      "probeless_msgs/TrackingStatus: integrated and relocalised must be 0 or 1");
  status.integrated = 0;
  status.SetReasonText(std::string(500, 'r'));  // cut, not refused
  EXPECT_EQ(status.ReasonText().size(), kTrackingReasonCapacity - 1);
  EXPECT_NO_THROW(status.Validate());
  EXPECT_NE(TrackingStatus::LayoutDescription().find(
                "state:TrackingStatusState{invalid=0,tracked=1,uncertain=2,lost=3}:u32@56;"),
            std::string::npos);
}

TEST(ReplayMessagesTest, AckTopicFitsEveryBusTopicName) {
  static_assert(kTopicNameCapacity > bus::kMaxNameLength);
  Ack ack;
  ack.SetTopic(std::string(bus::kMaxNameLength, 'a'));
  EXPECT_EQ(ack.Topic().size(), bus::kMaxNameLength);
  EXPECT_THROW(ack.SetTopic(std::string(kTopicNameCapacity, 'a')), MessageError);
  EXPECT_NE(PlayerControl::LayoutDescription().find("command:PlayerCommand{invalid=0,pause=1"),
            std::string::npos);
}

TEST(LayoutHashTest, DescriptionsListEveryField) {
  EXPECT_EQ(Header::LayoutDescription(),
            "probeless_msgs/Header{stamp_ns:i64@0;stamp_mono_ns:i64@8;sequence:u64@16;"
            "frame_id:char[32]@24;}size=56,align=8");
  const std::string image = Image::LayoutDescription();
  for (const char* field :
       {"header:probeless_msgs/Header{", "width:u32@56;", "height:u32@60;", "step:u32@64;",
        "encoding:Encoding{invalid=0,rgb8=1,bgr8=2,mono8=3,mono16=4,depth16=5,float32=6,rgb32f=7}:"
        "u32@68;",
        "reserved:u8[56]@72;"}) {
    EXPECT_NE(image.find(field), std::string::npos) << field << " in " << image;
  }
  const std::string face = FaceObservation::LayoutDescription();
  EXPECT_NE(face.find("landmarks:f32[68][2]@64;"), std::string::npos) << face;
  EXPECT_NE(face.find("sample_valid:u64[8]@12960;"), std::string::npos) << face;
}

TEST(LayoutHashTest, TopicTypeOfCarriesNameAndHash) {
  const bus::TopicType type = TopicTypeOf<Image>();
  EXPECT_EQ(type.name, "probeless_msgs/Image");
  EXPECT_EQ(type.layout_hash, Image::kLayoutHash);
  EXPECT_EQ(TopicTypeOf<ShLight>().name, "probeless_msgs/ShLight");
}

// --- Generic views and strings -------------------------------------------------------------------

TEST(MessageViewTest, WriteZeroesTheStructAndLeavesThePayload) {
  Slot slot(Image::MessageBytesFor(640, 480, Encoding::kRgb8));
  WriteView<Image> out = WriteMessage<Image>(slot.bytes());
  EXPECT_EQ(out.message->width, 0u);
  EXPECT_EQ(out.message->header.sequence, 0u);
  EXPECT_EQ(out.message->reserved[55], 0u);
  EXPECT_EQ(reinterpret_cast<std::byte*>(out.message), slot.bytes().data());
  EXPECT_EQ(out.payload.data(), slot.bytes().data() + 128);
  EXPECT_EQ(out.payload.size(), 921'600u);
  EXPECT_EQ(out.payload[0], std::byte{0xAB});
  out->Init(640, 480, Encoding::kRgb8);
  out->header.sequence = 7;

  ReadView<Image> in = ReadMessage<Image>(slot.cbytes());
  EXPECT_EQ(in->header.sequence, 7u);
  EXPECT_EQ(in->step, 1920u);
  EXPECT_EQ(in.payload.size(), 921'600u);
  EXPECT_NO_THROW(in->Validate(in.payload.size()));
}

TEST(MessageViewTest, RejectsShortOrMisalignedBytes) {
  Slot slot(256);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ReadMessage<Image>(slot.cbytes().first(100)), MessageError,
      "probeless_msgs/Image: message of 100 bytes is smaller than its fixed part (128 "
      "bytes)");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      WriteMessage<Pose>(slot.bytes().first(175)), MessageError,
      "probeless_msgs/Pose: message of 175 bytes is smaller than its fixed part (176 bytes)");
  PROBELESS_EXPECT_THROWS_MESSAGE(ReadMessage<Image>(slot.cbytes().subspan(8)), MessageError,
                                  "probeless_msgs/Image: message bytes are not 64-byte aligned");
  EXPECT_EQ(ReadMessage<Pose>(slot.cbytes().first(176)).payload.size(), 0u);
}

TEST(FixedStringTest, RoundTripsAndRejectsLongOrNulStrings) {
  Header header;
  header.SetFrameId("camera_optical");
  EXPECT_EQ(header.FrameId(), "camera_optical");
  header.SetFrameId(std::string(31, 'x'));
  EXPECT_EQ(header.FrameId(), std::string(31, 'x'));
  header.SetFrameId("a");
  EXPECT_EQ(header.FrameId(), "a");
  EXPECT_EQ(header.frame_id[2], '\0');  // the old tail is cleared
  PROBELESS_EXPECT_THROWS_MESSAGE(
      header.SetFrameId(std::string(32, 'y')), MessageError,
      "frame_id '" + std::string(32, 'y') + "' has 32 characters, at most 31 fit");
  PROBELESS_EXPECT_THROWS_MESSAGE(header.SetFrameId(std::string_view("a\0b", 3)), MessageError,
                                  "frame_id contains a NUL character");
  // An unterminated field (from a foreign writer) is read up to its capacity, never beyond.
  std::memset(header.frame_id, 'z', sizeof(header.frame_id));
  EXPECT_EQ(header.FrameId(), std::string(32, 'z'));
}

TEST(HeaderTest, StampNowReadsBothClocks) {
  Header header;
  header.StampNow();
  timespec mono{};
  clock_gettime(CLOCK_MONOTONIC, &mono);
  const int64_t now_mono = mono.tv_sec * 1'000'000'000LL + mono.tv_nsec;
  EXPECT_GT(header.stamp_ns, 1'600'000'000LL * 1'000'000'000LL);  // after 2020
  EXPECT_LE(header.stamp_mono_ns, now_mono);
  EXPECT_GT(header.stamp_mono_ns, now_mono - 1'000'000'000LL);
}

// --- Image -------------------------------------------------------------------------------------

TEST(ImageTest, SizeHelpers) {
  EXPECT_EQ(BytesPerPixel(Encoding::kRgb8), 3u);
  EXPECT_EQ(BytesPerPixel(Encoding::kBgr8), 3u);
  EXPECT_EQ(BytesPerPixel(Encoding::kMono8), 1u);
  EXPECT_EQ(BytesPerPixel(Encoding::kMono16), 2u);
  EXPECT_EQ(BytesPerPixel(Encoding::kDepth16), 2u);
  EXPECT_EQ(BytesPerPixel(Encoding::kFloat32), 4u);
  EXPECT_EQ(BytesPerPixel(Encoding::kRgb32f), 12u);
  EXPECT_EQ(ChannelCount(Encoding::kRgb32f), 3u);
  EXPECT_EQ(BytesPerPixel(Encoding::kInvalid), 0u);
  EXPECT_EQ(BytesPerPixel(static_cast<Encoding>(99)), 0u);
  EXPECT_EQ(Image::PackedPayloadBytes(640, 480, Encoding::kRgb8), 921'600u);
  EXPECT_EQ(Image::PackedPayloadBytes(640, 480, Encoding::kDepth16), 614'400u);
  EXPECT_EQ(Image::MessageBytesFor(640, 480, Encoding::kDepth16), 614'528u);
  Image image;
  image.Init(641, 3, Encoding::kFloat32);
  EXPECT_EQ(image.step, 2564u);
  EXPECT_EQ(image.PayloadBytes(), 7692u);
  PROBELESS_EXPECT_THROWS_MESSAGE(image.Init(1, 1, static_cast<Encoding>(9)), MessageError,
                                  "Image: invalid encoding 9");
}

TEST(ImageTest, EncodingNamesRoundTrip) {
  for (Encoding e : {Encoding::kRgb8, Encoding::kBgr8, Encoding::kMono8, Encoding::kMono16,
                     Encoding::kDepth16, Encoding::kFloat32, Encoding::kRgb32f}) {
    EXPECT_EQ(EncodingFromName(EncodingName(e)), e);
  }
  EXPECT_EQ(EncodingName(static_cast<Encoding>(42)), "invalid");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      EncodingFromName("16UC1"), MessageError,
      "unknown image encoding '16UC1' (expected rgb8, bgr8, mono8, mono16, depth16, float32 "
      "or rgb32f)");
}

TEST(ImageTest, Rgb32fRowsAreThreeFloatsPerPixel) {
  Slot slot(Image::MessageBytesFor(2, 2, Encoding::kRgb32f));
  WriteView<Image> out = WriteMessage<Image>(slot.bytes());
  out->Init(2, 2, Encoding::kRgb32f);
  EXPECT_EQ(out->step, 24u);
  std::span<float> row1 = ImageRow<float>(*out, out.payload, 1);
  ASSERT_EQ(row1.size(), 6u);
  row1[5] = 0.25f;  // pixel (1, 1), blue
  ReadView<Image> in = ReadMessage<Image>(slot.cbytes());
  EXPECT_EQ(ImageChannels<float>(*in, in.payload)[11], 0.25f);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ImageChannels<uint8_t>(*in, in.payload), MessageError,
      "Image 2x2 rgb32f (step 24): encoding rgb32f has float32 channels, not uint8");
}

TEST(ImageTest, TypedAccessorsHonourStepAndRejectBadRequests) {
  // 3x2 depth16 image with 4 bytes of row padding (step 10).
  Slot slot(sizeof(Image) + 20);
  WriteView<Image> out = WriteMessage<Image>(slot.bytes());
  out->Init(3, 2, Encoding::kDepth16);
  out->step = 10;
  std::span<uint16_t> all = ImageChannels<uint16_t>(*out, out.payload);
  ASSERT_EQ(all.size(), 10u);
  for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<uint16_t>(1000 + i);

  ReadView<Image> in = ReadMessage<Image>(slot.cbytes());
  std::span<const uint16_t> row1 = ImageRow<uint16_t>(*in, in.payload, 1);
  ASSERT_EQ(row1.size(), 3u);
  EXPECT_EQ(row1[0], 1005);  // row 1 starts at byte 10 = element 5
  EXPECT_EQ(row1[2], 1007);
  PROBELESS_EXPECT_THROWS_MESSAGE(ImageRow<uint16_t>(*in, in.payload, 2), MessageError,
                                  "Image 3x2 depth16 (step 10): row 2 out of range");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ImageChannels<float>(*in, in.payload), MessageError,
      "Image 3x2 depth16 (step 10): encoding depth16 has uint16 channels, not float32");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ImageChannels<uint8_t>(*in, in.payload), MessageError,
      "Image 3x2 depth16 (step 10): encoding depth16 has uint16 channels, not uint8");
  PROBELESS_EXPECT_THROWS_MESSAGE(ImageChannels<uint16_t>(*in, in.payload.first(19)), MessageError,
                                  "Image 3x2 depth16 (step 10) needs 20 payload bytes, got 19");

  Image bad = *in;
  bad.step = 5;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      bad.Validate(100), MessageError,
      "Image 3x2 depth16 (step 5): step 5 is smaller than width * 2 bytes per pixel");
  bad.step = 7;
  bad.width = 1;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      bad.Validate(100), MessageError,
      "Image 1x2 depth16 (step 7): step 7 is not a multiple of the 2-byte channel size");
}

TEST(ImageTest, FullVgaFramesFitAndAreRejectedWhenShort) {
  Slot slot(Image::MessageBytesFor(640, 480, Encoding::kRgb8));
  WriteView<Image> out = WriteMessage<Image>(slot.bytes());
  out->Init(640, 480, Encoding::kRgb8);
  std::span<uint8_t> rgb = ImageChannels<uint8_t>(*out, out.payload);
  EXPECT_EQ(rgb.size(), 921'600u);
  EXPECT_EQ(static_cast<void*>(rgb.data()), static_cast<void*>(out.payload.data()));
  EXPECT_EQ(ImageRow<uint8_t>(*out, out.payload, 479).size(), 1920u);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ImageChannels<uint8_t>(*out, out.payload.first(1000)), MessageError,
      "Image 640x480 rgb8 (step 1920) needs 921600 payload bytes, got 1000");

  out->Init(640, 480, Encoding::kDepth16);
  EXPECT_EQ(ImageChannels<uint16_t>(*out, out.payload.first(614'400)).size(), 307'200u);
}

// --- CameraInfo, Pose ----------------------------------------------------------------------------

TEST(CameraInfoTest, ValidateChecksModelAndCount) {
  CameraInfo info;
  info.header.SetFrameId("cam");
  info.width = 640;
  info.height = 480;
  info.fx = info.fy = 525;
  info.cx = 319.5;
  info.cy = 239.5;
  info.depth_scale = 0.001;
  EXPECT_NO_THROW(info.Validate());
  info.distortion_model = DistortionModel::kPlumbBob;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      info.Validate(), MessageError,
      "probeless_msgs/CameraInfo 'cam': distortion model plumb_bob has 5 coefficients, "
      "distortion_count is 0");
  info.distortion_count = 5;
  EXPECT_NO_THROW(info.Validate());
  EXPECT_EQ(DistortionCoefficientCount(DistortionModel::kRationalPolynomial), 8u);
  info.distortion_model = static_cast<DistortionModel>(3);
  PROBELESS_EXPECT_THROWS_MESSAGE(info.Validate(), MessageError,
                                  "probeless_msgs/CameraInfo 'cam': invalid distortion model 3");
  info.distortion_model = DistortionModel::kNone;
  info.distortion_count = 0;
  info.fx = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(info.Validate(), MessageError,
                                  "probeless_msgs/CameraInfo 'cam': fx and fy must be > 0");
}

TEST(PoseTest, TransformMapsChildPointsToParent) {
  Pose pose;
  pose.SetParentFrameId("world");
  pose.SetChildFrameId("camera");
  EXPECT_EQ(pose.header.FrameId(), "world");
  EXPECT_EQ(pose.ChildFrameId(), "camera");
  // Child rotated +90 degrees about the parent's z axis, origin at (1, 2, 3).
  const double h = std::sqrt(0.5);
  pose.transform = {{1, 2, 3}, {h, 0, 0, h}};
  const Vector3 p = pose.transform.Apply({1, 0, 0});  // child x axis -> parent y axis
  EXPECT_NEAR(p.x, 1.0, 1e-12);
  EXPECT_NEAR(p.y, 3.0, 1e-12);
  EXPECT_NEAR(p.z, 3.0, 1e-12);
  const Vector3 q = pose.transform.Apply({0, 0, 5});  // z is invariant under this rotation
  EXPECT_NEAR(q.x, 1.0, 1e-12);
  EXPECT_NEAR(q.y, 2.0, 1e-12);
  EXPECT_NEAR(q.z, 8.0, 1e-12);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      pose.SetChildFrameId(std::string(40, 'c')), MessageError,
      "child_frame_id '" + std::string(40, 'c') + "' has 40 characters, at most 31 fit");
}

// --- FaceObservation, ShLight ------------------------------------------------------------------

TEST(FaceObservationTest, ValidityBitsAndValidation) {
  auto face = std::make_unique<FaceObservation>();
  face->face_detected = 1;
  face->sample_count = 130;
  face->quality = 0.5f;
  face->SetSampleValid(0, true);
  face->SetSampleValid(64, true);
  face->SetSampleValid(129, true);
  face->SetSampleValid(65, true);
  face->SetSampleValid(65, false);
  EXPECT_TRUE(face->SampleValid(64));
  EXPECT_FALSE(face->SampleValid(65));
  EXPECT_EQ(face->sample_valid[1], 1u);
  EXPECT_EQ(face->sample_valid[2], 2u);
  EXPECT_EQ(face->ValidSampleCount(), 3u);
  EXPECT_NO_THROW(face->Validate());
  face->SetSampleValid(300, true);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      face->Validate(), MessageError,
      "probeless_msgs/FaceObservation: sample 300 flagged valid but sample_count is 130");
  EXPECT_EQ(face->ValidSampleCount(), 3u);  // bits beyond sample_count do not count
  PROBELESS_EXPECT_THROWS_MESSAGE(
      face->SetSampleValid(512, true), MessageError,
      "probeless_msgs/FaceObservation: sample index 512 out of range (max 511)");
  face->SetSampleValid(300, false);
  face->landmark_count = 69;
  PROBELESS_EXPECT_THROWS_MESSAGE(face->Validate(), MessageError,
                                  "probeless_msgs/FaceObservation: landmark_count 69 exceeds 68");
  face->landmark_count = 68;
  face->quality = 1.5f;
  PROBELESS_EXPECT_THROWS_MESSAGE(face->Validate(), MessageError,
                                  "probeless_msgs/FaceObservation: quality must be in [0, 1]");
}

TEST(ShLightTest, IndexingAndValidation) {
  EXPECT_EQ(ShCoefficientCount(3), 9u);
  EXPECT_EQ(ShCoefficientCount(5), kMaxShCoefficients);
  EXPECT_EQ(ShIndex(2, 0), 6u);
  EXPECT_EQ(ShIndex(3, -3), 9u);
  ShLight light;
  light.bands = 3;
  light.confidence = 1;
  EXPECT_EQ(light.CoefficientCount(), 9u);
  EXPECT_NO_THROW(light.Validate());
  light.bands = 6;
  PROBELESS_EXPECT_THROWS_MESSAGE(light.Validate(), MessageError,
                                  "probeless_msgs/ShLight: bands 6 out of range 1..5");
  light.bands = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(light.Validate(), MessageError,
                                  "probeless_msgs/ShLight: bands 0 out of range 1..5");
}

TEST(ShLightTest, UnitsFieldReplacesTheReservedWord) {
  // Value-initialised (and every message recorded before the field: its reserved zero) = unknown.
  ShLight light;
  EXPECT_EQ(light.units, ShLightUnits::kUnknown);
  EXPECT_NE(ShLight::LayoutDescription().find(
                "units:ShLightUnits{unknown=0,linear=1,face_model=2,linear_unscaled=3}:u32@60;"),
            std::string::npos);
  EXPECT_EQ(ShLight::LayoutDescription().find("reserved"), std::string::npos);
  light.bands = 3;
  for (ShLightUnits u : {ShLightUnits::kUnknown, ShLightUnits::kLinear, ShLightUnits::kFaceModel,
                         ShLightUnits::kLinearUnscaled}) {
    light.units = u;
    EXPECT_NO_THROW(light.Validate());
    EXPECT_EQ(ShLightUnitsFromName(ShLightUnitsName(u)), u);
  }
  light.units = static_cast<ShLightUnits>(4);
  EXPECT_EQ(ShLightUnitsName(light.units), "");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      light.Validate(), MessageError,
      "probeless_msgs/ShLight: units 4 is not unknown (0), linear (1), face_model (2) or "
      "linear_unscaled (3)");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ShLightUnitsFromName("gamma"), MessageError,
      "probeless_msgs/ShLight: units 'gamma' is not unknown, linear, face_model or "
      "linear_unscaled");
  // The bytes of a pre-field message (reserved0 = 0 at offset 60) read as kUnknown.
  alignas(64) std::byte bytes[sizeof(ShLight)] = {};
  EXPECT_EQ(ReadMessage<ShLight>(std::span<const std::byte>(bytes))->units, ShLightUnits::kUnknown);
}

// --- GeometryBuffer, TransferBuffer --------------------------------------------------------------

TEST(GeometryBufferTest, StandardLayoutPlanesAreAlignedAndDisjoint) {
  GeometryBuffer g;
  g.Init(5, 3);
  EXPECT_EQ(g.depth_offset, 0u);
  EXPECT_EQ(g.normals_offset, 64u);        // 60 depth bytes rounded up
  EXPECT_EQ(g.colour_offset, 64u + 192u);  // 180 normal bytes rounded up
  EXPECT_EQ(g.PayloadBytes(), 256u + 45u);
  EXPECT_EQ(GeometryBuffer::StandardPayloadBytes(5, 3), 301u);
  EXPECT_EQ(GeometryBuffer::MessageBytesFor(640, 480), 128u + 1'228'800u + 3'686'400u + 921'600u);

  Slot slot(GeometryBuffer::MessageBytesFor(5, 3));
  WriteView<GeometryBuffer> out = WriteMessage<GeometryBuffer>(slot.bytes());
  out->Init(5, 3);
  std::span<float> depth = DepthPlane(*out, out.payload);
  std::span<float> normals = NormalsPlane(*out, out.payload);
  std::span<uint8_t> colour = ColourPlane(*out, out.payload);
  EXPECT_EQ(depth.size(), 15u);
  EXPECT_EQ(normals.size(), 45u);
  EXPECT_EQ(colour.size(), 45u);
  for (float& d : depth) d = 1.5f;
  for (float& n : normals) n = -1.0f;
  for (uint8_t& c : colour) c = 200;
  ReadView<GeometryBuffer> in = ReadMessage<GeometryBuffer>(slot.cbytes());
  EXPECT_EQ(DepthPlane(*in, in.payload)[14], 1.5f);
  EXPECT_EQ(NormalsPlane(*in, in.payload)[0], -1.0f);
  EXPECT_EQ(ColourPlane(*in, in.payload)[44], 200);
}

TEST(GeometryBufferTest, RejectsShortPayloadOverlapAndMisalignment) {
  GeometryBuffer g;
  g.Init(5, 3);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      g.Validate(300), MessageError,
      "probeless_msgs/GeometryBuffer 5x3: colour plane (offset 256, 45 bytes) exceeds the "
      "payload of 300 bytes");
  g.normals_offset = 32;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      g.Validate(1000), MessageError,
      "probeless_msgs/GeometryBuffer 5x3: depth and normals planes overlap");
  g.normals_offset = 66;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      g.Validate(1000), MessageError,
      "probeless_msgs/GeometryBuffer 5x3: depth and normals offsets must be multiples of 4");
  g.normals_offset = ~uint64_t{0} - 3;  // would wrap around in a naive end computation
  PROBELESS_EXPECT_THROWS_MESSAGE(
      g.Validate(1000), MessageError,
      "probeless_msgs/GeometryBuffer 5x3: normals plane (offset 18446744073709551612, 180 "
      "bytes) exceeds the payload of 1000 bytes");
}

// --- AuxiliaryViews
// --------------------------------------------------------------------------------

// Two views (left 5x3, top 4x4) with a 90-degree rotation about y and a translation.
void FillTwoViews(AuxiliaryViews& a) {
  a.header.SetFrameId("camera_optical");
  a.header.stamp_ns = 1234;
  a.view_count = 2;
  const float rot[9] = {0, 0, 1, 0, 1, 0, -1, 0, 0};
  a.views[0].role = AuxiliaryViewRole::kLeft;
  a.views[0].width = 5;
  a.views[0].height = 3;
  a.views[1].role = AuxiliaryViewRole::kTop;
  a.views[1].width = 4;
  a.views[1].height = 4;
  for (uint32_t i = 0; i < 2; ++i) {
    a.views[i].pixel_size_m = 0.03f;
    std::copy(rot, rot + 9, a.views[i].rotation);
    a.views[i].translation[0] = -1.5f;
    a.views[i].translation[2] = 2.0f + i;
  }
  a.SetStandardLayout();
}

TEST(AuxiliaryViewsTest, RoundTripThroughASlot) {
  EXPECT_EQ(AuxiliaryViews::StandardPayloadBytes(3, 128, 128), 2u * 65536 + 65536);
  EXPECT_EQ(AuxiliaryViews::MessageBytesFor(3, 5, 3), 384u + 64 + 64 + 60);
  Slot slot(AuxiliaryViews::MessageBytesFor(2, 5, 4));
  WriteView<AuxiliaryViews> out = WriteMessage<AuxiliaryViews>(slot.bytes());
  FillTwoViews(*out);
  EXPECT_EQ(out->views[1].depth_offset, 64u);  // 60 bytes rounded up
  EXPECT_EQ(out->PayloadBytes(), 64u + 64);
  std::span<float> d0 = AuxiliaryDepth(*out, out.payload, 0);
  std::span<float> d1 = AuxiliaryDepth(*out, out.payload, 1);
  ASSERT_EQ(d0.size(), 15u);
  ASSERT_EQ(d1.size(), 16u);
  for (size_t i = 0; i < d0.size(); ++i) d0[i] = 0.5f + i;
  for (size_t i = 0; i < d1.size(); ++i) d1[i] = 2.0f + i;

  ReadView<AuxiliaryViews> in = ReadMessage<AuxiliaryViews>(slot.cbytes());
  EXPECT_EQ(in->header.FrameId(), "camera_optical");
  EXPECT_EQ(in->header.stamp_ns, 1234);
  ASSERT_EQ(in->view_count, 2u);
  EXPECT_EQ(in->views[0].role, AuxiliaryViewRole::kLeft);
  EXPECT_EQ(in->views[1].role, AuxiliaryViewRole::kTop);
  EXPECT_EQ(in->views[1].translation[2], 3.0f);
  EXPECT_EQ(in->views[0].rotation[2], 1.0f);
  EXPECT_EQ(AuxiliaryDepth(*in, in.payload, 0)[14], 14.5f);
  EXPECT_EQ(AuxiliaryDepth(*in, in.payload, 1)[15], 17.0f);
  PROBELESS_EXPECT_THROWS_MESSAGE(AuxiliaryDepth(*in, in.payload, 2), MessageError,
                                  "probeless_msgs/AuxiliaryViews: view 2 of 2");
  EXPECT_NE(AuxiliaryViews::LayoutDescription().find(
                "role:AuxiliaryViewRole{invalid=0,left=1,right=2,top=3,light=4}:u32@0"),
            std::string::npos);
}

TEST(AuxiliaryViewsTest, MalformedMessagesAreRejectedWithOneLine) {
  AuxiliaryViews a;
  FillTwoViews(a);
  const size_t bytes = a.PayloadBytes();
  EXPECT_NO_THROW(a.Validate(bytes));
  PROBELESS_EXPECT_THROWS_MESSAGE(
      a.Validate(bytes - 1), MessageError,
      "probeless_msgs/AuxiliaryViews view 1 (top 4x4): depth plane (offset 64, 64 bytes) "
      "exceeds the payload of 127 bytes");
  AuxiliaryViews b = a;
  b.view_count = 5;
  PROBELESS_EXPECT_THROWS_MESSAGE(b.Validate(bytes), MessageError,
                                  "probeless_msgs/AuxiliaryViews: view_count 5 exceeds 4");
  b = a;
  b.views[1].role = static_cast<AuxiliaryViewRole>(9);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      b.Validate(bytes), MessageError,
      "probeless_msgs/AuxiliaryViews view 1 (invalid 4x4): unknown role 9");
  b = a;
  b.views[0].width = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      b.Validate(bytes), MessageError,
      "probeless_msgs/AuxiliaryViews view 0 (left 0x3): width and height must be in 1..4096");
  b = a;
  b.views[0].pixel_size_m = std::nanf("");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      b.Validate(bytes), MessageError,
      "probeless_msgs/AuxiliaryViews view 0 (left 5x3): pixel_size_m must be finite and > 0");
  b = a;
  b.views[0].rotation[0] = 0.5f;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      b.Validate(bytes), MessageError,
      "probeless_msgs/AuxiliaryViews view 0 (left 5x3): rotation is not orthonormal");
  b = a;
  b.views[1].translation[1] = INFINITY;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      b.Validate(bytes), MessageError,
      "probeless_msgs/AuxiliaryViews view 1 (top 4x4): non-finite translation");
  b = a;
  b.views[1].depth_offset = 32;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      b.Validate(bytes), MessageError,
      "probeless_msgs/AuxiliaryViews view 1 (top 4x4): depth plane overlaps view 0's");
  b.views[1].depth_offset = 66;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      b.Validate(bytes), MessageError,
      "probeless_msgs/AuxiliaryViews view 1 (top 4x4): depth offset must be a multiple of 4");
  b.views[1].depth_offset = ~uint64_t{0} - 3;  // would wrap around in a naive end computation
  PROBELESS_EXPECT_THROWS_MESSAGE(
      b.Validate(bytes), MessageError,
      "probeless_msgs/AuxiliaryViews view 1 (top 4x4): depth plane (offset "
      "18446744073709551612, 64 bytes) exceeds the payload of 128 bytes");
  b.view_count = 0;  // no views: valid, empty payload
  EXPECT_NO_THROW(b.Validate(0));
}

TEST(TransferBufferTest, SizesIndexingAndErrors) {
  EXPECT_EQ(TransferBuffer::PayloadBytesFor(640, 480, 9), 640u * 480 * 9 * 4);
  Slot slot(TransferBuffer::MessageBytesFor(4, 3, 16));
  WriteView<TransferBuffer> out = WriteMessage<TransferBuffer>(slot.bytes());
  out->Init(4, 3, 16);
  std::span<float> all = TransferCoefficients(*out, out.payload);
  ASSERT_EQ(all.size(), 4u * 3 * 16);
  for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<float>(i);
  ReadView<TransferBuffer> in = ReadMessage<TransferBuffer>(slot.cbytes());
  std::span<const float> pixel = PixelTransfer(*in, in.payload, 2, 1);
  ASSERT_EQ(pixel.size(), 16u);
  EXPECT_EQ(pixel[0], static_cast<float>((1 * 4 + 2) * 16));
  EXPECT_EQ(pixel[15], static_cast<float>((1 * 4 + 2) * 16 + 15));
  PROBELESS_EXPECT_THROWS_MESSAGE(PixelTransfer(*in, in.payload, 4, 0), MessageError,
                                  "probeless_msgs/TransferBuffer: pixel (4, 0) outside 4x3");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      TransferCoefficients(*in, in.payload.first(100)), MessageError,
      "probeless_msgs/TransferBuffer 4x3 x 16 needs 768 payload bytes, got 100");
  TransferBuffer t;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      t.Init(4, 3, 10), MessageError,
      "probeless_msgs/TransferBuffer: coefficient_count 10 is not 1, 4, 9, 16 or 25");
  PROBELESS_EXPECT_THROWS_MESSAGE(t.Validate(0), MessageError,
                                  "probeless_msgs/TransferBuffer 0x0: unknown layout 0");
}

}  // namespace
}  // namespace probeless::msgs
