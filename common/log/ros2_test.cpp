// ROS 2 conversions: schemas, CDR layouts of the standard types, lossless round trips of the
// probeless_msgs/msg types, and decode errors.
#include "probeless/log/ros2.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "probeless/log/cdr.h"
#include "probeless/msgs/msgs.h"
#include "probeless/testing/expect.h"

namespace probeless::log {
namespace {

namespace m = probeless::msgs;
using ::testing::HasSubstr;

std::mt19937 rng(42);
float RandomFloat() { return std::uniform_real_distribution<float>(-1.0f, 1.0f)(rng); }

void FillHeader(m::Header& header, int64_t stamp_ns, const char* frame) {
  header.stamp_ns = stamp_ns;
  header.stamp_mono_ns = 42'000'000'123;
  header.sequence = 99;
  header.SetFrameId(frame);
}

MessageBuffer MakeImage(m::Encoding encoding, uint32_t width, uint32_t height, uint32_t padding) {
  const uint32_t step = width * m::BytesPerPixel(encoding) + padding;
  MessageBuffer buffer(sizeof(m::Image) + static_cast<size_t>(step) * height);
  auto image = m::WriteMessage<m::Image>(buffer.bytes());
  FillHeader(image->header, 1'700'000'000'987'654'321, "camera_optical");
  image->Init(width, height, encoding);
  image->step = step;
  for (std::byte& b : image.payload) b = static_cast<std::byte>(rng() & 0xFF);
  return buffer;
}

// ---- schemas ----

TEST(Ros2ConvertersTest, EveryTypeHasOneConverter) {
  const auto all = AllRos2Converters();
  ASSERT_EQ(all.size(), 8u);
  std::set<std::string_view> probeless_types;
  std::set<std::string_view> ros2_types;
  for (const Ros2Converter* converter : all) {
    probeless_types.insert(converter->probeless_type());
    ros2_types.insert(converter->ros2_type());
    EXPECT_EQ(FindRos2ConverterByProbelessType(converter->probeless_type()), converter);
    EXPECT_EQ(FindRos2ConverterByRos2Type(converter->ros2_type()), converter);
  }
  EXPECT_EQ(probeless_types.size(), 8u);
  EXPECT_EQ(ros2_types,
            (std::set<std::string_view>{
                "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo",
                "geometry_msgs/msg/PoseStamped", "probeless_msgs/msg/FaceObservation",
                "probeless_msgs/msg/ShLight", "probeless_msgs/msg/GeometryBuffer",
                "probeless_msgs/msg/TransferBuffer", "probeless_msgs/msg/TrackingStatus"}));
  EXPECT_EQ(Ros2ConverterFor<m::Image>().ros2_type(), "sensor_msgs/msg/Image");
  EXPECT_EQ(Ros2ConverterFor<m::Pose>().layout_hash(), m::Pose::kLayoutHash);
  EXPECT_EQ(FindRos2ConverterByRos2Type("std_msgs/msg/String"), nullptr);
  PROBELESS_EXPECT_THROWS_MESSAGE(Ros2ConverterForType("probeless_msgs/Header"), CdrError,
                                  "no ROS 2 conversion for probeless type 'probeless_msgs/Header'");
}

// Splits a concatenated ros2msg schema into (type name, definition) sections.
std::vector<std::pair<std::string, std::string>> Sections(std::string_view schema,
                                                          std::string_view main_name) {
  std::vector<std::pair<std::string, std::string>> sections{{std::string(main_name), ""}};
  std::istringstream lines{std::string(schema)};
  std::string line;
  while (std::getline(lines, line)) {
    if (line == std::string(80, '=')) {
      sections.emplace_back("", "");
    } else if (line.rfind("MSG: ", 0) == 0) {
      EXPECT_TRUE(sections.back().first.empty() && sections.back().second.empty()) << line;
      sections.back().first = line.substr(5);
    } else {
      EXPECT_EQ(line.find('='), std::string::npos) << "stray separator: " << line;
      sections.back().second += line + "\n";
    }
  }
  return sections;
}

TEST(Ros2ConvertersTest, SchemasAreCompleteConcatenatedRos2Msg) {
  const std::set<std::string> primitives = {"bool",    "int8",   "uint8", "int16",  "uint16",
                                            "int32",   "uint32", "int64", "uint64", "float32",
                                            "float64", "string", "byte",  "char"};
  for (const Ros2Converter* converter : AllRos2Converters()) {
    SCOPED_TRACE(std::string(converter->ros2_type()));
    const auto sections = Sections(converter->schema_text(), converter->ros2_type());
    std::set<std::string> defined;
    for (const auto& [name, text] : sections) {
      ASSERT_FALSE(name.empty());
      ASSERT_FALSE(text.empty()) << name;
      // "pkg/msg/Type" and "pkg/Type" name the same type.
      std::string short_name = name;
      const size_t msg = short_name.find("/msg/");
      if (msg != std::string::npos) short_name.erase(msg, 4);
      EXPECT_TRUE(defined.insert(short_name).second) << "defined twice: " << name;
    }
    for (const auto& [name, text] : sections) {
      std::istringstream lines(text);
      std::string line;
      while (std::getline(lines, line)) {
        if (line.empty() || line[0] == '#') continue;
        std::istringstream fields(line);
        std::string type;
        std::string field;
        fields >> type >> field;
        ASSERT_FALSE(field.empty()) << "line without a field name: " << line;
        const std::string base = type.substr(0, type.find('['));
        if (primitives.count(base) == 0) {
          EXPECT_EQ(defined.count(base), 1u) << name << " uses undefined type " << base;
        }
      }
    }
  }
}

// ---- sensor_msgs/msg/Image ----

TEST(ImageConversionTest, EveryEncodingRoundTripsWithItsRosName) {
  const std::pair<m::Encoding, const char*> encodings[] = {
      {m::Encoding::kRgb8, "rgb8"},     {m::Encoding::kBgr8, "bgr8"},
      {m::Encoding::kMono8, "mono8"},   {m::Encoding::kMono16, "mono16"},
      {m::Encoding::kDepth16, "16UC1"}, {m::Encoding::kFloat32, "32FC1"}};
  const Ros2Converter& converter = Ros2ConverterFor<m::Image>();
  for (const auto& [encoding, ros_name] : encodings) {
    SCOPED_TRACE(ros_name);
    const MessageBuffer original = MakeImage(encoding, 13, 7, 2 * m::BytesPerChannel(encoding));
    const auto in = m::ReadMessage<m::Image>(original.bytes());
    const std::vector<std::byte> cdr = EncodeRos2(converter, original.bytes());

    // The sensor_msgs/Image layout, field by field.
    CdrReader reader(cdr, "check");
    EXPECT_EQ(reader.Read<int32_t>("sec"), 1'700'000'000);
    EXPECT_EQ(reader.Read<uint32_t>("nanosec"), 987'654'321u);
    EXPECT_EQ(reader.String("frame_id"), "camera_optical");
    EXPECT_EQ(reader.Read<uint32_t>("height"), 7u);
    EXPECT_EQ(reader.Read<uint32_t>("width"), 13u);
    EXPECT_EQ(reader.String("encoding"), ros_name);
    EXPECT_EQ(reader.Read<uint8_t>("is_bigendian"), 0);
    EXPECT_EQ(reader.Read<uint32_t>("step"), in->step);
    const auto data = reader.SequenceBytes<uint8_t>("data");
    ASSERT_EQ(data.size(), in->PayloadBytes());
    EXPECT_EQ(std::memcmp(data.data(), in.payload.data(), data.size()), 0);
    EXPECT_EQ(reader.remaining(), 0u);

    const MessageBuffer decoded = DecodeRos2(converter, cdr);
    ASSERT_EQ(decoded.size(), original.size());
    const auto out = m::ReadMessage<m::Image>(decoded.bytes());
    EXPECT_EQ(out->header.stamp_ns, in->header.stamp_ns);
    EXPECT_EQ(out->header.stamp_mono_ns, 0);  // not carried by std_msgs/Header
    EXPECT_EQ(out->header.sequence, 0u);
    EXPECT_EQ(out->header.FrameId(), "camera_optical");
    EXPECT_EQ(out->width, in->width);
    EXPECT_EQ(out->height, in->height);
    EXPECT_EQ(out->step, in->step);
    EXPECT_EQ(out->encoding, encoding);
    EXPECT_EQ(std::memcmp(out.payload.data(), in.payload.data(), in->PayloadBytes()), 0);
  }
}

TEST(CompressedImageTest, LayoutAndSchema) {
  m::Header header;
  header.stamp_ns = 1'700'000'000'987'654'321;
  header.SetFrameId("camera_optical");
  const std::byte jpeg[] = {std::byte{0xff}, std::byte{0xd8}, std::byte{0xff}, std::byte{0xd9}};
  CdrWriter out;
  EncodeCompressedImage(header, "jpeg", jpeg, out);
  CdrReader reader(out.data(), "check");
  EXPECT_EQ(reader.Read<int32_t>("sec"), 1'700'000'000);
  EXPECT_EQ(reader.Read<uint32_t>("nanosec"), 987'654'321u);
  EXPECT_EQ(reader.String("frame_id"), "camera_optical");
  EXPECT_EQ(reader.String("format"), "jpeg");
  const auto data = reader.SequenceBytes<uint8_t>("data");
  ASSERT_EQ(data.size(), sizeof(jpeg));
  EXPECT_EQ(std::memcmp(data.data(), jpeg, sizeof(jpeg)), 0);
  EXPECT_EQ(reader.remaining(), 0u);
  // The same dependency texts as the Image schema.
  const std::string image_schema(Ros2ConverterFor<m::Image>().schema_text());
  const std::string& schema = CompressedImageSchemaText();
  EXPECT_THAT(schema,
              ::testing::StartsWith("std_msgs/Header header\nstring format\nuint8[] data\n"));
  EXPECT_EQ(schema.substr(schema.find("====")), image_schema.substr(image_schema.find("====")));
}

TEST(ImageConversionTest, DecodeErrors) {
  const Ros2Converter& converter = Ros2ConverterFor<m::Image>();
  auto image_cdr = [](const std::string& encoding, uint8_t big_endian, uint32_t step,
                      size_t data_bytes, const std::string& frame = "cam") {
    CdrWriter w;
    w.Write<int32_t>(10);
    w.Write<uint32_t>(20);
    w.String(frame);
    w.Write<uint32_t>(2);  // height
    w.Write<uint32_t>(3);  // width
    w.String(encoding);
    w.Write<uint8_t>(big_endian);
    w.Write<uint32_t>(step);
    w.ByteSequence(std::vector<std::byte>(data_bytes));
    return w.Take();
  };
  EXPECT_EQ(DecodeRos2(converter, image_cdr("mono16", 0, 6, 12)).size(), sizeof(m::Image) + 12);
  EXPECT_EQ(DecodeRos2(converter, image_cdr("rgb8", 1, 9, 18)).size(), sizeof(m::Image) + 18);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      DecodeRos2(converter, image_cdr("yuv422", 0, 6, 12)), CdrError,
      "CDR sensor_msgs/msg/Image: field 'encoding' at offset 39: unsupported image "
      "encoding 'yuv422' (expected rgb8, bgr8, mono8, mono16, 16UC1, 32FC1 or 32FC3)");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      DecodeRos2(converter, image_cdr("mono16", 1, 6, 12)), CdrError,
      "CDR sensor_msgs/msg/Image: field 'is_bigendian' at offset 40: big-endian mono16 "
      "pixels are not supported");
  PROBELESS_EXPECT_THROWS_MESSAGE_THAT(
      DecodeRos2(converter, image_cdr("mono16", 0, 6, 11)), CdrError,
      HasSubstr("field 'data' at offset 59: 11 bytes, but step * height = 12"));
  PROBELESS_EXPECT_THROWS_MESSAGE(
      DecodeRos2(converter, image_cdr("mono16", 0, 4, 8)), CdrError,
      "CDR sensor_msgs/msg/Image: decoded message invalid: Image 3x2 mono16 (step 4): step "
      "4 is smaller than width * 2 bytes per pixel");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      DecodeRos2(converter, image_cdr("mono8", 0, 3, 6, std::string(40, 'f'))), CdrError,
      "CDR sensor_msgs/msg/Image: field 'header.frame_id' at offset 57: '" + std::string(40, 'f') +
          "' does not fit a probeless frame id (at most 31 characters, no NUL)");
  const std::vector<std::byte> cdr = image_cdr("mono8", 0, 3, 6);
  MessageBuffer small(sizeof(m::Image));
  PROBELESS_EXPECT_THROWS_MESSAGE(
      converter.Decode(cdr, {}, small.bytes()), CdrError,
      "CDR sensor_msgs/msg/Image: output of 128 bytes is smaller than the 134 bytes of the "
      "decoded probeless_msgs/Image");
}

TEST(ImageConversionTest, EncodeRejectsInvalidImages) {
  const Ros2Converter& converter = Ros2ConverterFor<m::Image>();
  MessageBuffer buffer(sizeof(m::Image) + 10);
  auto image = m::WriteMessage<m::Image>(buffer.bytes());
  image->Init(4, 4, m::Encoding::kMono8);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      EncodeRos2(converter, buffer.bytes()), CdrError,
      "CDR sensor_msgs/msg/Image: Image 4x4 mono8 (step 4) needs 16 payload bytes, got 10");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      EncodeRos2(converter, buffer.bytes().first(100)), CdrError,
      "CDR sensor_msgs/msg/Image: probeless_msgs/Image: message of 100 bytes is smaller than "
      "its fixed part (128 bytes)");
}

TEST(HeaderConversionTest, StampsBeforeTheEpochAndOutOfRange) {
  const Ros2Converter& converter = Ros2ConverterFor<m::Pose>();
  MessageBuffer buffer(sizeof(m::Pose));
  auto pose = m::WriteMessage<m::Pose>(buffer.bytes());
  pose->header.stamp_ns = -1;
  pose->SetParentFrameId("world");
  const std::vector<std::byte> cdr = EncodeRos2(converter, buffer.bytes());
  CdrReader reader(cdr, "check");
  EXPECT_EQ(reader.Read<int32_t>("sec"), -1);
  EXPECT_EQ(reader.Read<uint32_t>("nanosec"), 999'999'999u);
  EXPECT_EQ(m::ReadMessage<m::Pose>(DecodeRos2(converter, cdr).bytes())->header.stamp_ns, -1);

  pose->header.stamp_ns = int64_t{1} << 62;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      EncodeRos2(converter, buffer.bytes()), CdrError,
      "CDR geometry_msgs/msg/PoseStamped: stamp 4611686018427387904 ns is outside the int32 "
      "seconds range of builtin_interfaces/Time");

  CdrWriter bad;
  bad.Write<int32_t>(0);
  bad.Write<uint32_t>(1'000'000'000);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      converter.DecodedSize(bad.data()), CdrError,
      "CDR geometry_msgs/msg/PoseStamped: field 'header.stamp.nanosec' at offset 12: "
      "1000000000 is not below 1e9");
}

// ---- sensor_msgs/msg/CameraInfo ----

TEST(CameraInfoConversionTest, IntrinsicsDistortionAndDepthScale) {
  const Ros2Converter& converter = Ros2ConverterFor<m::CameraInfo>();
  for (m::DistortionModel model : {m::DistortionModel::kNone, m::DistortionModel::kPlumbBob,
                                   m::DistortionModel::kRationalPolynomial}) {
    SCOPED_TRACE(std::string(m::DistortionModelName(model)));
    MessageBuffer buffer(sizeof(m::CameraInfo));
    auto info = m::WriteMessage<m::CameraInfo>(buffer.bytes());
    FillHeader(info->header, 5'000'000'001, "camera_depth");
    info->width = 640;
    info->height = 480;
    info->fx = 610.5;
    info->fy = 611.25;
    info->cx = 318.75;
    info->cy = 242.5;
    info->distortion_model = model;
    info->distortion_count = m::DistortionCoefficientCount(model);
    for (uint32_t i = 0; i < info->distortion_count; ++i) info->distortion[i] = RandomFloat();
    info->depth_scale = 0.001;

    const std::vector<std::byte> cdr = EncodeRos2(converter, buffer.bytes());
    CdrReader reader(cdr, "check");
    reader.Read<int32_t>("sec");
    reader.Read<uint32_t>("nanosec");
    reader.String("frame_id");
    EXPECT_EQ(reader.Read<uint32_t>("height"), 480u);
    EXPECT_EQ(reader.Read<uint32_t>("width"), 640u);
    EXPECT_EQ(reader.String("distortion_model"),
              model == m::DistortionModel::kNone ? "" : m::DistortionModelName(model));
    const std::vector<double> d = reader.Sequence<double>("d");
    EXPECT_EQ(d, std::vector<double>(info->distortion, info->distortion + info->distortion_count));
    double k[9];
    double r[9];
    double p[12];
    reader.Array(std::span<double>(k), "k");
    reader.Array(std::span<double>(r), "r");
    reader.Array(std::span<double>(p), "p");
    EXPECT_THAT(k, ::testing::ElementsAre(610.5, 0, 318.75, 0, 611.25, 242.5, 0, 0, 1));
    EXPECT_THAT(r, ::testing::ElementsAre(1, 0, 0, 0, 1, 0, 0, 0, 1));
    EXPECT_THAT(p, ::testing::ElementsAre(610.5, 0, 318.75, 0, 0, 611.25, 242.5, 0, 0, 0, 1, 0));
    EXPECT_EQ(reader.Read<uint32_t>("binning_x"), 0u);
    EXPECT_EQ(reader.Read<uint32_t>("binning_y"), 0u);
    for (int i = 0; i < 4; ++i) EXPECT_EQ(reader.Read<uint32_t>("roi"), 0u);
    EXPECT_FALSE(reader.Bool("do_rectify"));
    EXPECT_EQ(reader.remaining(), 0u);

    const auto metadata = converter.ChannelMetadata(buffer.bytes());
    EXPECT_EQ(metadata.at("probeless.type"), "probeless_msgs/CameraInfo");
    EXPECT_EQ(metadata.at("probeless.depth_scale"), "0.001");
    MessageBuffer decoded = DecodeRos2(converter, cdr, metadata);
    auto out = m::ReadMessage<m::CameraInfo>(decoded.bytes());
    m::CameraInfo expected = *info;
    expected.header.stamp_mono_ns = 0;
    expected.header.sequence = 0;
    EXPECT_EQ(std::memcmp(&*out, &expected, sizeof(expected)), 0);
    // Without the metadata the depth scale is unknown (0).
    EXPECT_EQ(m::ReadMessage<m::CameraInfo>(DecodeRos2(converter, cdr).bytes())->depth_scale, 0);
  }
}

TEST(CameraInfoConversionTest, DistortionCountMustMatchTheModel) {
  const Ros2Converter& converter = Ros2ConverterFor<m::CameraInfo>();
  auto info_cdr = [](const std::string& model, std::vector<double> d) {
    CdrWriter w;
    w.Write<int32_t>(0);
    w.Write<uint32_t>(0);
    w.String("cam");
    w.Write<uint32_t>(480);
    w.Write<uint32_t>(640);
    w.String(model);
    w.Sequence(std::span<const double>(d));
    const double k[9] = {500, 0, 320, 0, 500, 240, 0, 0, 1};
    w.Array(std::span<const double>(k));
    w.Array(std::span<const double>(std::vector<double>(21)));
    for (int i = 0; i < 6; ++i) w.Write<uint32_t>(0);
    w.Bool(false);
    return w.Take();
  };
  PROBELESS_EXPECT_THROWS_MESSAGE(
      DecodeRos2(converter, info_cdr("plumb_bob", {0.1, 0.2})), CdrError,
      "CDR sensor_msgs/msg/CameraInfo: field 'd' at offset 68: distortion model "
      "'plumb_bob' has 5 coefficients, d has 2");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      DecodeRos2(converter, info_cdr("fisheye", {})), CdrError,
      "CDR sensor_msgs/msg/CameraInfo: field 'distortion_model' at offset 40: unsupported "
      "distortion model 'fisheye' (expected '', plumb_bob or rational_polynomial)");
  // Uncalibrated drivers send plumb_bob with an empty d: accepted as zeros.
  const MessageBuffer zeros = DecodeRos2(converter, info_cdr("plumb_bob", {}));
  EXPECT_EQ(m::ReadMessage<m::CameraInfo>(zeros.bytes())->distortion_count, 5u);
}

// ---- geometry_msgs/msg/PoseStamped ----

TEST(PoseConversionTest, QuaternionOrderAndChildFrame) {
  const Ros2Converter& converter = Ros2ConverterFor<m::Pose>();
  MessageBuffer buffer(sizeof(m::Pose));
  auto pose = m::WriteMessage<m::Pose>(buffer.bytes());
  FillHeader(pose->header, 3'000'000'007, "world");
  pose->SetParentFrameId("world");
  pose->SetChildFrameId("camera_optical");
  pose->transform.translation = {1.5, -2.25, 3.125};
  pose->transform.rotation = {0.5, 0.5, -0.5, 0.5};  // w, x, y, z

  const std::vector<std::byte> cdr = EncodeRos2(converter, buffer.bytes());
  CdrReader reader(cdr, "check");
  EXPECT_EQ(reader.Read<int32_t>("sec"), 3);
  EXPECT_EQ(reader.Read<uint32_t>("nanosec"), 7u);
  EXPECT_EQ(reader.String("frame_id"), "world");
  const double expected[7] = {1.5, -2.25, 3.125, 0.5, -0.5, 0.5, 0.5};  // x y z, qx qy qz qw
  for (double value : expected) EXPECT_EQ(reader.Read<double>("pose"), value);
  EXPECT_EQ(reader.remaining(), 0u);

  const auto metadata = converter.ChannelMetadata(buffer.bytes());
  EXPECT_EQ(metadata.at("probeless.child_frame_id"), "camera_optical");
  const MessageBuffer decoded = DecodeRos2(converter, cdr, metadata);
  m::Pose want = *pose;
  want.header.stamp_mono_ns = 0;
  want.header.sequence = 0;
  EXPECT_EQ(std::memcmp(decoded.bytes().data(), &want, sizeof(want)), 0);
  EXPECT_EQ(m::ReadMessage<m::Pose>(DecodeRos2(converter, cdr).bytes())->ChildFrameId(), "");
}

// ---- probeless_msgs/msg types: lossless ----

MessageBuffer MakeFace() {
  MessageBuffer buffer(sizeof(m::FaceObservation));
  auto face = m::WriteMessage<m::FaceObservation>(buffer.bytes());
  FillHeader(face->header, 1'234'567'890'123'456'789, "camera_color");
  face->face_detected = 1;
  face->landmark_count = 68;
  for (auto& landmark : face->landmarks) {
    landmark[0] = 320 + 100 * RandomFloat();
    landmark[1] = 240 + 100 * RandomFloat();
  }
  face->head_pose.translation = {0.01, 0.02, 0.55};
  face->head_pose.rotation = {0.9, 0.1, 0.3, std::sqrt(1 - 0.81 - 0.01 - 0.09)};
  face->sample_count = 300;
  face->quality = 0.8f;
  for (uint32_t i = 0; i < face->sample_count; ++i) {
    for (int c = 0; c < 3; ++c) {
      face->sample_rgb[i][c] = std::abs(RandomFloat());
      face->sample_normals[i][c] = RandomFloat();
    }
    face->SetSampleValid(i, rng() % 4 != 0);
  }
  return buffer;
}

MessageBuffer MakeLight() {
  MessageBuffer buffer(sizeof(m::ShLight));
  auto light = m::WriteMessage<m::ShLight>(buffer.bytes());
  FillHeader(light->header, 77, "world");
  light->bands = 4;
  for (uint32_t i = 0; i < 16; ++i) {
    for (int c = 0; c < 3; ++c) light->coefficients[i][c] = RandomFloat();
  }
  light->dominant_direction[2] = -1;
  light->intensity = 3.5f;
  light->confidence = 0.25f;
  light->units = m::ShLightUnits::kLinear;
  return buffer;
}

MessageBuffer MakeGeometry() {
  MessageBuffer buffer(m::GeometryBuffer::MessageBytesFor(17, 9));
  auto g = m::WriteMessage<m::GeometryBuffer>(buffer.bytes());
  FillHeader(g->header, 88, "camera_depth");
  g->Init(17, 9);
  for (float& v : m::DepthPlane(*g, g.payload)) v = 1 + RandomFloat();
  for (float& v : m::NormalsPlane(*g, g.payload)) v = RandomFloat();
  for (uint8_t& v : m::ColourPlane(*g, g.payload)) v = static_cast<uint8_t>(rng());
  return buffer;
}

MessageBuffer MakeTransfer() {
  MessageBuffer buffer(m::TransferBuffer::MessageBytesFor(6, 5, 16));
  auto t = m::WriteMessage<m::TransferBuffer>(buffer.bytes());
  FillHeader(t->header, 99, "camera_depth");
  t->Init(6, 5, 16);
  for (float& v : m::TransferCoefficients(*t, t.payload)) v = RandomFloat();
  return buffer;
}

MessageBuffer MakeTracking() {
  MessageBuffer buffer(sizeof(m::TrackingStatus));
  auto t = m::WriteMessage<m::TrackingStatus>(buffer.bytes());
  FillHeader(t->header, 77, "camera_depth");
  t->state = m::TrackingStatusState::kUncertain;
  t->score = 0.3f;
  t->reasons = m::kTrackingReasonMotion | m::kTrackingReasonDegenerate;
  t->relocalised = 1;
  t->rms_m = RandomFloat();
  t->observability = 0.004f;
  t->frames = 12;
  t->lost_frames = 3;
  t->relocalisations = 1;
  t->SetReasonText("step 7.0 cm off the constant-velocity prediction (soft 5.0 cm)");
  return buffer;
}

TEST(ProbelessTypesConversionTest, RoundTripsAreByteExact) {
  const std::pair<std::string_view, MessageBuffer> messages[] = {
      {m::FaceObservation::kTypeName, MakeFace()},
      {m::ShLight::kTypeName, MakeLight()},
      {m::GeometryBuffer::kTypeName, MakeGeometry()},
      {m::TransferBuffer::kTypeName, MakeTransfer()},
      {m::TrackingStatus::kTypeName, MakeTracking()}};
  for (const auto& [type, original] : messages) {
    SCOPED_TRACE(std::string(type));
    const Ros2Converter& converter = Ros2ConverterForType(type);
    EXPECT_EQ(converter.ros2_type().substr(0, 19), "probeless_msgs/msg/");
    const std::vector<std::byte> cdr = EncodeRos2(converter, original.bytes());
    EXPECT_EQ(converter.DecodedSize(cdr), original.size());
    const MessageBuffer decoded = DecodeRos2(converter, cdr);
    ASSERT_EQ(decoded.size(), original.size());
    EXPECT_EQ(std::memcmp(decoded.bytes().data(), original.bytes().data(), original.size()), 0);
  }
}

TEST(ProbelessTypesConversionTest, ShLightRecordedBeforeTheUnitsFieldDecodesAsUnknown) {
  const MessageBuffer original = MakeLight();
  const Ros2Converter& converter = Ros2ConverterFor<m::ShLight>();
  EXPECT_NE(converter.schema_text().find("uint32 units"), std::string_view::npos);
  const std::vector<std::byte> cdr = EncodeRos2(converter, original.bytes());
  // The old encoding: the same bytes without the trailing uint32.
  const MessageBuffer old = DecodeRos2(converter, std::span(cdr.data(), cdr.size() - 4));
  const auto light = m::ReadMessage<m::ShLight>(old.bytes());
  EXPECT_EQ(light->units, m::ShLightUnits::kUnknown);
  EXPECT_EQ(light->bands, 4u);
  EXPECT_EQ(light->confidence, 0.25f);
  EXPECT_EQ(light->coefficients[15][2],
            m::ReadMessage<m::ShLight>(original.bytes())->coefficients[15][2]);
  EXPECT_EQ(m::ReadMessage<m::ShLight>(DecodeRos2(converter, cdr).bytes())->units,
            m::ShLightUnits::kLinear);
  // A value outside the enum is refused by name.
  std::vector<std::byte> bad = cdr;
  bad[bad.size() - 4] = std::byte{9};
  PROBELESS_EXPECT_THROWS_MESSAGE(
      DecodeRos2(converter, bad), CdrError,
      "CDR probeless_msgs/msg/ShLight: decoded message invalid: probeless_msgs/ShLight: "
      "units 9 is not unknown (0), linear (1), face_model (2) or linear_unscaled (3)");
}

TEST(ProbelessTypesConversionTest, FaceObservationLayout) {
  const MessageBuffer original = MakeFace();
  const auto face = m::ReadMessage<m::FaceObservation>(original.bytes());
  const std::vector<std::byte> cdr =
      EncodeRos2(Ros2ConverterFor<m::FaceObservation>(), original.bytes());
  CdrReader reader(cdr, "check");
  EXPECT_EQ(reader.Read<int32_t>("sec"), 1'234'567'890);
  EXPECT_EQ(reader.Read<uint32_t>("nanosec"), 123'456'789u);
  EXPECT_EQ(reader.String("frame_id"), "camera_color");
  EXPECT_EQ(reader.Read<int64_t>("stamp_mono_ns"), 42'000'000'123);
  EXPECT_EQ(reader.Read<uint64_t>("sequence"), 99u);
  EXPECT_TRUE(reader.Bool("face_detected"));
  const std::vector<float> landmarks = reader.Sequence<float>("landmarks");
  ASSERT_EQ(landmarks.size(), 136u);
  EXPECT_EQ(landmarks[5], face->landmarks[2][1]);
  for (int i = 0; i < 7; ++i) reader.Read<double>("head_pose");
  EXPECT_EQ(reader.Read<float>("quality"), 0.8f);
  EXPECT_EQ(reader.Sequence<float>("sample_rgb").size(), 900u);
  EXPECT_EQ(reader.Sequence<float>("sample_normals").size(), 900u);
  const uint32_t flags = reader.Read<uint32_t>("sample_valid");
  ASSERT_EQ(flags, 300u);
  for (uint32_t i = 0; i < flags; ++i) EXPECT_EQ(reader.Bool("flag"), face->SampleValid(i));
  EXPECT_EQ(reader.remaining(), 0u);
}

TEST(ProbelessTypesConversionTest, InconsistentSizesAreRejected) {
  CdrWriter w;
  w.Write<int32_t>(0);
  w.Write<uint32_t>(0);
  w.String("cam");
  w.Write<int64_t>(0);
  w.Write<uint64_t>(0);
  w.Write<uint32_t>(2);  // width
  w.Write<uint32_t>(2);  // height
  w.Write<uint32_t>(9);  // coefficient_count
  w.Sequence(std::span<const float>(std::vector<float>(35)));
  PROBELESS_EXPECT_THROWS_MESSAGE(
      DecodeRos2(Ros2ConverterFor<m::TransferBuffer>(), w.data()), CdrError,
      "CDR probeless_msgs/msg/TransferBuffer: field 'coefficients' at offset 192: 35 "
      "values, width * height * coefficient_count = 36");

  CdrWriter light;
  light.Write<int32_t>(0);
  light.Write<uint32_t>(0);
  light.String("cam");
  light.Write<int64_t>(0);
  light.Write<uint64_t>(0);
  light.Write<uint32_t>(7);  // bands
  PROBELESS_EXPECT_THROWS_MESSAGE(
      DecodeRos2(Ros2ConverterFor<m::ShLight>(), light.data()), CdrError,
      "CDR probeless_msgs/msg/ShLight: field 'bands' at offset 40: 7 out of range 1..5");

  CdrWriter geometry;
  geometry.Write<int32_t>(0);
  geometry.Write<uint32_t>(0);
  geometry.String("cam");
  geometry.Write<int64_t>(0);
  geometry.Write<uint64_t>(0);
  geometry.Write<uint32_t>(0xFFFFFFFF);
  geometry.Write<uint32_t>(0xFFFFFFFF);
  PROBELESS_EXPECT_THROWS_MESSAGE_THAT(
      DecodeRos2(Ros2ConverterFor<m::GeometryBuffer>(), geometry.data()), CdrError,
      HasSubstr("field 'height' at offset 44: 18446744065119617025 pixels are too many"));

  MessageBuffer bad_light = MakeLight();
  reinterpret_cast<m::ShLight*>(bad_light.bytes().data())->bands = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      EncodeRos2(Ros2ConverterFor<m::ShLight>(), bad_light.bytes()), CdrError,
      "CDR probeless_msgs/msg/ShLight: probeless_msgs/ShLight: bands 0 out of range 1..5");
}

TEST(Ros2ConvertersTest, EveryTruncatedMessageIsACleanError) {
  const std::pair<std::string_view, MessageBuffer> messages[] = {
      {m::Image::kTypeName, MakeImage(m::Encoding::kDepth16, 5, 4, 0)},
      {m::FaceObservation::kTypeName, MakeFace()},
      {m::ShLight::kTypeName, MakeLight()},
      {m::GeometryBuffer::kTypeName, MakeGeometry()},
      {m::TransferBuffer::kTypeName, MakeTransfer()}};
  for (const auto& [type, original] : messages) {
    const Ros2Converter& converter = Ros2ConverterForType(type);
    const std::vector<std::byte> cdr = EncodeRos2(converter, original.bytes());
    for (size_t cut = 0; cut < cdr.size(); ++cut) {
      // A light that ends after `confidence` is one recorded before the units field (below).
      if (type == m::ShLight::kTypeName && cut == cdr.size() - 4) continue;
      const std::string error = probeless::testing::ThrownMessage<CdrError>(
          [&] { DecodeRos2(converter, std::span(cdr.data(), cut)); });
      ASSERT_EQ(error.rfind("CDR " + std::string(converter.ros2_type()) + ": ", 0), 0u)
          << type << " cut at " << cut << ": " << error;
    }
  }
}

}  // namespace
}  // namespace probeless::log
