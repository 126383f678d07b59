#include "probeless/log/ros2.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <initializer_list>
#include <new>
#include <string>

#include "probeless/msgs/camera_info.h"
#include "probeless/msgs/face_observation.h"
#include "probeless/msgs/geometry_buffer.h"
#include "probeless/msgs/image.h"
#include "probeless/msgs/pose.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/msgs/tracking_status.h"
#include "probeless/msgs/transfer_buffer.h"

namespace probeless::log {
namespace {

namespace m = probeless::msgs;

constexpr int64_t kNanosPerSecond = 1'000'000'000;
// Pixel count limit of the plane types (as msgs::GeometryBuffer::Validate); keeps size products
// from overflowing.
constexpr uint64_t kMaxPixels = uint64_t{1} << 40;

// ---- Schema texts (ros2msg) ----

constexpr std::string_view kSeparator =
    "================================================================================\n";

struct Definition {
  std::string_view name;  // "std_msgs/Header": as written after "MSG: "
  std::string_view text;  // the definition, one field per line
};

constexpr Definition kTime{"builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"};
constexpr Definition kStdHeader{"std_msgs/Header",
                                "builtin_interfaces/Time stamp\nstring frame_id\n"};
constexpr Definition kPoint{"geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"};
constexpr Definition kQuaternion{"geometry_msgs/Quaternion",
                                 "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"};
constexpr Definition kPose{"geometry_msgs/Pose",
                           "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n"};
constexpr Definition kRegionOfInterest{
    "sensor_msgs/RegionOfInterest",
    "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"};

// The main definition followed by its dependencies in the concatenated ros2msg format.
std::string ComposeSchema(std::string_view main, std::initializer_list<Definition> dependencies) {
  std::string text(main);
  for (const Definition& dependency : dependencies) {
    text += kSeparator;
    text += "MSG: ";
    text += dependency.name;
    text += "\n";
    text += dependency.text;
  }
  return text;
}

// ---- Shared field helpers ----

[[noreturn]] void Throw(std::string_view ros2_type, const std::string& problem) {
  throw CdrError("CDR " + std::string(ros2_type) + ": " + problem);
}

std::string HexHash(uint64_t hash) {
  char text[24];
  std::snprintf(text, sizeof(text), "0x%016llx", static_cast<unsigned long long>(hash));
  return text;
}

void WriteStamp(CdrWriter& out, int64_t stamp_ns, std::string_view ros2_type) {
  int64_t seconds = stamp_ns / kNanosPerSecond;
  int64_t nanos = stamp_ns % kNanosPerSecond;
  if (nanos < 0) {
    nanos += kNanosPerSecond;
    seconds -= 1;
  }
  if (seconds < INT32_MIN || seconds > INT32_MAX) {
    Throw(ros2_type, "stamp " + std::to_string(stamp_ns) +
                         " ns is outside the int32 seconds range of builtin_interfaces/Time");
  }
  out.Write<int32_t>(static_cast<int32_t>(seconds));
  out.Write<uint32_t>(static_cast<uint32_t>(nanos));
}

int64_t ReadStamp(CdrReader& in) {
  const int32_t seconds = in.Read<int32_t>("header.stamp.sec");
  const uint32_t nanos = in.Read<uint32_t>("header.stamp.nanosec");
  if (nanos >= kNanosPerSecond) {
    in.Fail("header.stamp.nanosec", std::to_string(nanos) + " is not below 1e9");
  }
  return int64_t{seconds} * kNanosPerSecond + nanos;
}

// std_msgs/Header from a probeless Header (stamp_mono_ns and sequence are not carried).
void WriteStdHeader(CdrWriter& out, const m::Header& header, std::string_view ros2_type) {
  WriteStamp(out, header.stamp_ns, ros2_type);
  out.String(header.FrameId());
}

void SetFrame(char (&field)[m::kFrameIdCapacity], const std::string& value, CdrReader& in,
              std::string_view name) {
  if (value.size() >= m::kFrameIdCapacity || value.find('\0') != std::string::npos) {
    in.Fail(name,
            "'" + value + "' does not fit a probeless frame id (at most 31 characters, no NUL)");
  }
  m::SetFixedString(field, value, name);
}

void ReadStdHeader(CdrReader& in, m::Header& header) {
  header.stamp_ns = ReadStamp(in);
  SetFrame(header.frame_id, in.String("header.frame_id"), in, "header.frame_id");
}

// std_msgs/Header + int64 stamp_mono_ns + uint64 sequence (the probeless_msgs/msg types).
void WriteFullHeader(CdrWriter& out, const m::Header& header, std::string_view ros2_type) {
  WriteStdHeader(out, header, ros2_type);
  out.Write<int64_t>(header.stamp_mono_ns);
  out.Write<uint64_t>(header.sequence);
}

void ReadFullHeader(CdrReader& in, m::Header& header) {
  ReadStdHeader(in, header);
  header.stamp_mono_ns = in.Read<int64_t>("stamp_mono_ns");
  header.sequence = in.Read<uint64_t>("sequence");
}

constexpr std::string_view kFullHeaderFields =
    "std_msgs/Header header\n"
    "int64 stamp_mono_ns   # the stamp on CLOCK_MONOTONIC, nanoseconds\n"
    "uint64 sequence       # producer's sequence number of the data (0: unset)\n";

// geometry_msgs/Pose from a RigidTransform (quaternion order x, y, z, w in ROS).
void WritePose(CdrWriter& out, const m::RigidTransform& transform) {
  out.Write<double>(transform.translation.x);
  out.Write<double>(transform.translation.y);
  out.Write<double>(transform.translation.z);
  out.Write<double>(transform.rotation.x);
  out.Write<double>(transform.rotation.y);
  out.Write<double>(transform.rotation.z);
  out.Write<double>(transform.rotation.w);
}

m::RigidTransform ReadPose(CdrReader& in, std::string_view prefix) {
  const std::string p(prefix);
  m::RigidTransform transform;
  transform.translation.x = in.Read<double>(p + ".position.x");
  transform.translation.y = in.Read<double>(p + ".position.y");
  transform.translation.z = in.Read<double>(p + ".position.z");
  transform.rotation.x = in.Read<double>(p + ".orientation.x");
  transform.rotation.y = in.Read<double>(p + ".orientation.y");
  transform.rotation.z = in.Read<double>(p + ".orientation.z");
  transform.rotation.w = in.Read<double>(p + ".orientation.w");
  return transform;
}

// Copies a float32 sequence's raw bytes into `out` (count elements).
void CopyFloats(std::span<const std::byte> bytes, float* out) {
  if (!bytes.empty()) std::memcpy(out, bytes.data(), bytes.size());
}

// ---- Converter skeleton ----

// Fields: the parsed CDR message (views into the input); Parse, SizeOf and Fill define a type.
template <class M, class Fields>
class TypedConverter : public Ros2Converter {
 public:
  TypedConverter(std::string_view ros2_type, std::string schema)
      : ros2_type_(ros2_type), schema_(std::move(schema)) {}

  std::string_view probeless_type() const override { return M::kTypeName; }
  uint64_t layout_hash() const override { return M::kLayoutHash; }
  std::string_view ros2_type() const override { return ros2_type_; }
  std::string_view schema_text() const override { return schema_; }

  void Encode(std::span<const std::byte> message, CdrWriter& out) const override {
    const m::ReadView<M> view = View(message);
    out.Reset();
    try {
      Write(*view, view.payload, out);
    } catch (const m::MessageError& error) {
      Throw(ros2_type_, error.what());
    }
  }

  size_t DecodedSize(std::span<const std::byte> cdr) const override {
    CdrReader in(cdr, ros2_type_);
    return SizeOf(Parse(in));
  }

  size_t Decode(std::span<const std::byte> cdr,
                const std::map<std::string, std::string>& channel_metadata,
                std::span<std::byte> out) const override {
    CdrReader in(cdr, ros2_type_);
    const Fields fields = Parse(in);
    const size_t size = SizeOf(fields);
    if (out.size() < size) {
      Throw(ros2_type_, "output of " + std::to_string(out.size()) + " bytes is smaller than the " +
                            std::to_string(size) + " bytes of the decoded " +
                            std::string(M::kTypeName));
    }
    try {
      const m::WriteView<M> view = m::WriteMessage<M>(out.first(size));
      Fill(fields, channel_metadata, *view, view.payload);
      Check(*view, view.payload);
    } catch (const m::MessageError& error) {
      Throw(ros2_type_, "decoded message invalid: " + std::string(error.what()));
    }
    return size;
  }

 protected:
  virtual void Write(const M& message, std::span<const std::byte> payload,
                     CdrWriter& out) const = 0;
  virtual Fields Parse(CdrReader& in) const = 0;
  virtual size_t SizeOf(const Fields&) const { return sizeof(M); }
  virtual void Fill(const Fields& fields, const std::map<std::string, std::string>& metadata,
                    M& message, std::span<std::byte> payload) const = 0;
  // Validates a decoded message (throws msgs::MessageError).
  virtual void Check(const M& message, std::span<const std::byte> payload) const {}

  m::ReadView<M> View(std::span<const std::byte> message) const {
    try {
      return m::ReadMessage<M>(message);
    } catch (const m::MessageError& error) {
      Throw(ros2_type_, error.what());
    }
  }

  std::string_view ros2_type_;
  std::string schema_;
};

// ---- sensor_msgs/msg/Image ----

std::string_view Ros2ImageEncoding(m::Encoding encoding) {
  switch (encoding) {
    case m::Encoding::kRgb8:
      return "rgb8";
    case m::Encoding::kBgr8:
      return "bgr8";
    case m::Encoding::kMono8:
      return "mono8";
    case m::Encoding::kMono16:
      return "mono16";
    case m::Encoding::kDepth16:
      return "16UC1";
    case m::Encoding::kFloat32:
      return "32FC1";
    case m::Encoding::kRgb32f:
      return "32FC3";
    case m::Encoding::kInvalid:
      break;
  }
  return "";
}

struct ImageFields {
  m::Header header;
  uint32_t height = 0;
  uint32_t width = 0;
  m::Encoding encoding = m::Encoding::kInvalid;
  uint32_t step = 0;
  std::span<const std::byte> data;
};

class ImageConverter : public TypedConverter<m::Image, ImageFields> {
 public:
  ImageConverter()
      : TypedConverter("sensor_msgs/msg/Image", ComposeSchema("std_msgs/Header header\n"
                                                              "uint32 height\n"
                                                              "uint32 width\n"
                                                              "string encoding\n"
                                                              "uint8 is_bigendian\n"
                                                              "uint32 step\n"
                                                              "uint8[] data\n",
                                                              {kStdHeader, kTime})) {}

 protected:
  void Write(const m::Image& image, std::span<const std::byte> payload,
             CdrWriter& out) const override {
    image.Validate(payload.size());
    out.Reserve(64 + image.PayloadBytes());
    WriteStdHeader(out, image.header, ros2_type_);
    out.Write<uint32_t>(image.height);
    out.Write<uint32_t>(image.width);
    out.String(Ros2ImageEncoding(image.encoding));
    out.Write<uint8_t>(0);  // is_bigendian: probeless pixels are little-endian
    out.Write<uint32_t>(image.step);
    out.ByteSequence(payload.first(image.PayloadBytes()));
  }

  ImageFields Parse(CdrReader& in) const override {
    ImageFields f;
    ReadStdHeader(in, f.header);
    f.height = in.Read<uint32_t>("height");
    f.width = in.Read<uint32_t>("width");
    const std::string encoding = in.String("encoding");
    for (m::Encoding e :
         {m::Encoding::kRgb8, m::Encoding::kBgr8, m::Encoding::kMono8, m::Encoding::kMono16,
          m::Encoding::kDepth16, m::Encoding::kFloat32, m::Encoding::kRgb32f}) {
      if (Ros2ImageEncoding(e) == encoding) f.encoding = e;
    }
    if (f.encoding == m::Encoding::kInvalid) {
      in.Fail("encoding", "unsupported image encoding '" + encoding +
                              "' (expected rgb8, bgr8, mono8, mono16, 16UC1, 32FC1 or 32FC3)");
    }
    const uint8_t big_endian = in.Read<uint8_t>("is_bigendian");
    if (big_endian != 0 && m::BytesPerChannel(f.encoding) > 1) {
      in.Fail("is_bigendian", "big-endian " + encoding + " pixels are not supported");
    }
    f.step = in.Read<uint32_t>("step");
    f.data = in.SequenceBytes<uint8_t>("data");
    const uint64_t expected = uint64_t{f.step} * f.height;
    if (f.data.size() != expected) {
      in.Fail("data", std::to_string(f.data.size()) +
                          " bytes, but step * height = " + std::to_string(expected));
    }
    return f;
  }

  size_t SizeOf(const ImageFields& f) const override { return sizeof(m::Image) + f.data.size(); }

  void Fill(const ImageFields& f, const std::map<std::string, std::string>&, m::Image& image,
            std::span<std::byte> payload) const override {
    image.header = f.header;
    image.width = f.width;
    image.height = f.height;
    image.step = f.step;
    image.encoding = f.encoding;
    if (!f.data.empty()) std::memcpy(payload.data(), f.data.data(), f.data.size());
  }

  void Check(const m::Image& image, std::span<const std::byte> payload) const override {
    image.Validate(payload.size());
  }
};

// ---- sensor_msgs/msg/CameraInfo ----

struct CameraInfoFields {
  m::Header header;
  uint32_t height = 0;
  uint32_t width = 0;
  m::DistortionModel model = m::DistortionModel::kNone;
  std::vector<double> d;
  double k[9] = {};
};

double ParseDouble(const std::string& text, std::string_view ros2_type, std::string_view key) {
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size()) {
    Throw(ros2_type, "channel metadata " + std::string(key) + " '" + text + "' is not a number");
  }
  return value;
}

std::string FormatDouble(double value) {
  char text[40];
  std::snprintf(text, sizeof(text), "%.17g", value);
  return text;
}

class CameraInfoConverter : public TypedConverter<m::CameraInfo, CameraInfoFields> {
 public:
  CameraInfoConverter()
      : TypedConverter("sensor_msgs/msg/CameraInfo",
                       ComposeSchema("std_msgs/Header header\n"
                                     "uint32 height\n"
                                     "uint32 width\n"
                                     "string distortion_model\n"
                                     "float64[] d\n"
                                     "float64[9] k\n"
                                     "float64[9] r\n"
                                     "float64[12] p\n"
                                     "uint32 binning_x\n"
                                     "uint32 binning_y\n"
                                     "sensor_msgs/RegionOfInterest roi\n",
                                     {kStdHeader, kTime, kRegionOfInterest})) {}

  std::map<std::string, std::string> ChannelMetadata(
      std::span<const std::byte> message) const override {
    auto metadata = Ros2Converter::ChannelMetadata(message);
    metadata[std::string(kMetadataDepthScale)] = FormatDouble(View(message)->depth_scale);
    return metadata;
  }

 protected:
  void Write(const m::CameraInfo& info, std::span<const std::byte>, CdrWriter& out) const override {
    info.Validate();
    WriteStdHeader(out, info.header, ros2_type_);
    out.Write<uint32_t>(info.height);
    out.Write<uint32_t>(info.width);
    out.String(info.distortion_model == m::DistortionModel::kNone
                   ? std::string_view()
                   : m::DistortionModelName(info.distortion_model));
    out.Sequence(std::span<const double>(info.distortion, info.distortion_count));
    const double k[9] = {info.fx, 0, info.cx, 0, info.fy, info.cy, 0, 0, 1};
    const double r[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    const double p[12] = {info.fx, 0, info.cx, 0, 0, info.fy, info.cy, 0, 0, 0, 1, 0};
    out.Array(std::span<const double>(k));
    out.Array(std::span<const double>(r));
    out.Array(std::span<const double>(p));
    out.Write<uint32_t>(0);                              // binning_x: none
    out.Write<uint32_t>(0);                              // binning_y
    for (int i = 0; i < 4; ++i) out.Write<uint32_t>(0);  // roi: full image
    out.Bool(false);                                     // roi.do_rectify
  }

  CameraInfoFields Parse(CdrReader& in) const override {
    CameraInfoFields f;
    ReadStdHeader(in, f.header);
    f.height = in.Read<uint32_t>("height");
    f.width = in.Read<uint32_t>("width");
    const std::string model = in.String("distortion_model");
    if (model.empty() || model == "none") {
      f.model = m::DistortionModel::kNone;
    } else if (model == "plumb_bob") {
      f.model = m::DistortionModel::kPlumbBob;
    } else if (model == "rational_polynomial") {
      f.model = m::DistortionModel::kRationalPolynomial;
    } else {
      in.Fail("distortion_model", "unsupported distortion model '" + model +
                                      "' (expected '', plumb_bob or rational_polynomial)");
    }
    f.d = in.Sequence<double>("d");
    const uint32_t expected = m::DistortionCoefficientCount(f.model);
    // A missing or all-zero d is accepted for any model (uncalibrated drivers send that).
    const bool all_zero = std::all_of(f.d.begin(), f.d.end(), [](double v) { return v == 0; });
    if (f.d.size() != expected && !(all_zero && f.d.size() <= m::kMaxDistortionCoefficients)) {
      in.Fail("d", "distortion model '" + model + "' has " + std::to_string(expected) +
                       " coefficients, d has " + std::to_string(f.d.size()));
    }
    in.Array(std::span<double>(f.k), "k");
    double ignored[12];
    in.Array(std::span<double>(ignored, 9), "r");
    in.Array(std::span<double>(ignored, 12), "p");
    in.Read<uint32_t>("binning_x");
    in.Read<uint32_t>("binning_y");
    in.Read<uint32_t>("roi.x_offset");
    in.Read<uint32_t>("roi.y_offset");
    in.Read<uint32_t>("roi.height");
    in.Read<uint32_t>("roi.width");
    in.Bool("roi.do_rectify");
    return f;
  }

  void Fill(const CameraInfoFields& f, const std::map<std::string, std::string>& metadata,
            m::CameraInfo& info, std::span<std::byte>) const override {
    info.header = f.header;
    info.width = f.width;
    info.height = f.height;
    info.fx = f.k[0];
    info.cx = f.k[2];
    info.fy = f.k[4];
    info.cy = f.k[5];
    info.distortion_model = f.model;
    info.distortion_count = m::DistortionCoefficientCount(f.model);
    // Only the model's coefficients (an all-zero d of another length leaves them zero).
    for (size_t i = 0; i < f.d.size() && i < info.distortion_count; ++i) {
      info.distortion[i] = f.d[i];
    }
    const auto scale = metadata.find(std::string(kMetadataDepthScale));
    if (scale != metadata.end()) {
      info.depth_scale = ParseDouble(scale->second, ros2_type_, kMetadataDepthScale);
    }
  }

  void Check(const m::CameraInfo& info, std::span<const std::byte>) const override {
    info.Validate();
  }
};

// ---- geometry_msgs/msg/PoseStamped ----

struct PoseFields {
  m::Header header;
  m::RigidTransform transform;
};

class PoseConverter : public TypedConverter<m::Pose, PoseFields> {
 public:
  PoseConverter()
      : TypedConverter("geometry_msgs/msg/PoseStamped",
                       ComposeSchema("std_msgs/Header header\ngeometry_msgs/Pose pose\n",
                                     {kStdHeader, kTime, kPose, kPoint, kQuaternion})) {}

  std::map<std::string, std::string> ChannelMetadata(
      std::span<const std::byte> message) const override {
    auto metadata = Ros2Converter::ChannelMetadata(message);
    metadata[std::string(kMetadataChildFrameId)] = std::string(View(message)->ChildFrameId());
    return metadata;
  }

 protected:
  void Write(const m::Pose& pose, std::span<const std::byte>, CdrWriter& out) const override {
    // header.frame_id is the parent frame (Pose keeps both equal).
    m::Header header = pose.header;
    m::SetFixedString(header.frame_id, pose.ParentFrameId(), "parent_frame_id");
    WriteStdHeader(out, header, ros2_type_);
    WritePose(out, pose.transform);
  }

  PoseFields Parse(CdrReader& in) const override {
    PoseFields f;
    ReadStdHeader(in, f.header);
    f.transform = ReadPose(in, "pose");
    return f;
  }

  void Fill(const PoseFields& f, const std::map<std::string, std::string>& metadata, m::Pose& pose,
            std::span<std::byte>) const override {
    pose.header = f.header;
    pose.SetParentFrameId(f.header.FrameId());
    const auto child = metadata.find(std::string(kMetadataChildFrameId));
    if (child != metadata.end()) pose.SetChildFrameId(child->second);
    pose.transform = f.transform;
  }
};

// ---- probeless_msgs/msg/FaceObservation ----

struct FaceFields {
  m::Header header;
  bool face_detected = false;
  std::span<const std::byte> landmarks;  // float32 x, y pairs
  m::RigidTransform head_pose;
  float quality = 0;
  std::span<const std::byte> sample_rgb;      // float32 triples
  std::span<const std::byte> sample_normals;  // float32 triples
  std::vector<uint8_t> sample_valid;          // bools
};

class FaceObservationConverter : public TypedConverter<m::FaceObservation, FaceFields> {
 public:
  FaceObservationConverter()
      : TypedConverter(
            "probeless_msgs/msg/FaceObservation",
            ComposeSchema(
                std::string("# A tracked face in one camera image (probeless_msgs/FaceObservation)."
                            "\n") +
                    std::string(kFullHeaderFields) +
                    "bool face_detected\n"
                    "float32[] landmarks              # landmark i at pixel x landmarks[2i], y "
                    "landmarks[2i+1], iBUG 300-W order\n"
                    "geometry_msgs/Pose head_pose     # face frame -> camera frame, metres\n"
                    "float32 quality                  # 0..1\n"
                    "float32[] sample_rgb             # sample i: linear R, G, B at 3i..3i+2\n"
                    "float32[] sample_normals         # sample i: unit normal in the camera frame\n"
                    "bool[] sample_valid              # one flag per sample\n",
                {kStdHeader, kTime, kPose, kPoint, kQuaternion})) {}

 protected:
  void Write(const m::FaceObservation& face, std::span<const std::byte>,
             CdrWriter& out) const override {
    face.Validate();
    WriteFullHeader(out, face.header, ros2_type_);
    out.Bool(face.face_detected != 0);
    out.Sequence(std::span<const float>(&face.landmarks[0][0], face.landmark_count * 2));
    WritePose(out, face.head_pose);
    out.Write<float>(face.quality);
    out.Sequence(std::span<const float>(&face.sample_rgb[0][0], face.sample_count * 3));
    out.Sequence(std::span<const float>(&face.sample_normals[0][0], face.sample_count * 3));
    out.Write<uint32_t>(face.sample_count);
    for (uint32_t i = 0; i < face.sample_count; ++i) out.Bool(face.SampleValid(i));
  }

  FaceFields Parse(CdrReader& in) const override {
    FaceFields f;
    ReadFullHeader(in, f.header);
    f.face_detected = in.Bool("face_detected");
    f.landmarks = in.SequenceBytes<float>("landmarks");
    if (f.landmarks.size() % (2 * sizeof(float)) != 0 ||
        f.landmarks.size() > m::kMaxFaceLandmarks * 2 * sizeof(float)) {
      in.Fail("landmarks", std::to_string(f.landmarks.size() / sizeof(float)) +
                               " values: expected an even count of at most " +
                               std::to_string(m::kMaxFaceLandmarks * 2));
    }
    f.head_pose = ReadPose(in, "head_pose");
    f.quality = in.Read<float>("quality");
    f.sample_rgb = in.SequenceBytes<float>("sample_rgb");
    const size_t samples = f.sample_rgb.size() / (3 * sizeof(float));
    if (f.sample_rgb.size() % (3 * sizeof(float)) != 0 || samples > m::kMaxFaceSamples) {
      in.Fail("sample_rgb", std::to_string(f.sample_rgb.size() / sizeof(float)) +
                                " values: expected a multiple of 3, at most " +
                                std::to_string(m::kMaxFaceSamples * 3));
    }
    f.sample_normals = in.SequenceBytes<float>("sample_normals");
    if (f.sample_normals.size() != f.sample_rgb.size()) {
      in.Fail("sample_normals", std::to_string(f.sample_normals.size() / sizeof(float)) +
                                    " values, sample_rgb has " +
                                    std::to_string(f.sample_rgb.size() / sizeof(float)));
    }
    const uint32_t valid_count = in.Read<uint32_t>("sample_valid");
    if (valid_count != samples) {
      in.Fail("sample_valid",
              std::to_string(valid_count) + " flags for " + std::to_string(samples) + " samples");
    }
    f.sample_valid.resize(valid_count);
    for (uint32_t i = 0; i < valid_count; ++i) f.sample_valid[i] = in.Bool("sample_valid");
    return f;
  }

  void Fill(const FaceFields& f, const std::map<std::string, std::string>&,
            m::FaceObservation& face, std::span<std::byte>) const override {
    face.header = f.header;
    face.face_detected = f.face_detected ? 1 : 0;
    face.landmark_count = static_cast<uint32_t>(f.landmarks.size() / (2 * sizeof(float)));
    CopyFloats(f.landmarks, &face.landmarks[0][0]);
    face.head_pose = f.head_pose;
    face.quality = f.quality;
    face.sample_count = static_cast<uint32_t>(f.sample_valid.size());
    CopyFloats(f.sample_rgb, &face.sample_rgb[0][0]);
    CopyFloats(f.sample_normals, &face.sample_normals[0][0]);
    for (uint32_t i = 0; i < face.sample_count; ++i) face.SetSampleValid(i, f.sample_valid[i]);
  }

  void Check(const m::FaceObservation& face, std::span<const std::byte>) const override {
    face.Validate();
  }
};

// ---- probeless_msgs/msg/ShLight ----

struct ShLightFields {
  m::Header header;
  uint32_t bands = 0;
  std::span<const std::byte> coefficients;
  float dominant_direction[3] = {};
  float intensity = 0;
  float confidence = 0;
  m::ShLightUnits units = m::ShLightUnits::kUnknown;
};

// `units` is the last field, so a message recorded before it (ending after `confidence`) still
// decodes, as kUnknown (docs/log.md).
class ShLightConverter : public TypedConverter<m::ShLight, ShLightFields> {
 public:
  ShLightConverter()
      : TypedConverter(
            "probeless_msgs/msg/ShLight",
            ComposeSchema(
                std::string("# Incident light as RGB spherical harmonics (probeless_msgs/ShLight, "
                            "conventions in docs/messages.md).\n") +
                    std::string(kFullHeaderFields) +
                    "uint32 bands                    # 1..5\n"
                    "float32[] coefficients          # bands^2 x (R, G, B): index (l*(l+1)+m)*3+c\n"
                    "float32[3] dominant_direction   # unit vector towards the light, or 0\n"
                    "float32 intensity\n"
                    "float32 confidence              # 0..1\n"
                    "uint32 units                    # 0 unknown (recorded before the field), 1 "
                    "linear, 2 face_model, 3 linear_unscaled\n",
                {kStdHeader, kTime})) {}

 protected:
  void Write(const m::ShLight& light, std::span<const std::byte>, CdrWriter& out) const override {
    light.Validate();
    WriteFullHeader(out, light.header, ros2_type_);
    out.Write<uint32_t>(light.bands);
    out.Sequence(std::span<const float>(&light.coefficients[0][0], light.CoefficientCount() * 3));
    out.Array(std::span<const float>(light.dominant_direction));
    out.Write<float>(light.intensity);
    out.Write<float>(light.confidence);
    out.Write<uint32_t>(static_cast<uint32_t>(light.units));
  }

  ShLightFields Parse(CdrReader& in) const override {
    ShLightFields f;
    ReadFullHeader(in, f.header);
    f.bands = in.Read<uint32_t>("bands");
    if (f.bands < 1 || f.bands > m::kMaxShBands) {
      in.Fail("bands", std::to_string(f.bands) + " out of range 1..5");
    }
    f.coefficients = in.SequenceBytes<float>("coefficients");
    const size_t expected = m::ShCoefficientCount(f.bands) * 3;
    if (f.coefficients.size() != expected * sizeof(float)) {
      in.Fail("coefficients", std::to_string(f.coefficients.size() / sizeof(float)) + " values, " +
                                  std::to_string(f.bands) + " bands need " +
                                  std::to_string(expected));
    }
    in.Array(std::span<float>(f.dominant_direction), "dominant_direction");
    f.intensity = in.Read<float>("intensity");
    f.confidence = in.Read<float>("confidence");
    if (in.remaining() > 0) f.units = static_cast<m::ShLightUnits>(in.Read<uint32_t>("units"));
    return f;
  }

  void Fill(const ShLightFields& f, const std::map<std::string, std::string>&, m::ShLight& light,
            std::span<std::byte>) const override {
    light.header = f.header;
    light.bands = f.bands;
    CopyFloats(f.coefficients, &light.coefficients[0][0]);
    std::copy(std::begin(f.dominant_direction), std::end(f.dominant_direction),
              light.dominant_direction);
    light.intensity = f.intensity;
    light.confidence = f.confidence;
    light.units = f.units;
  }

  void Check(const m::ShLight& light, std::span<const std::byte>) const override {
    light.Validate();
  }
};

// ---- probeless_msgs/msg/GeometryBuffer ----

struct GeometryFields {
  m::Header header;
  uint32_t width = 0;
  uint32_t height = 0;
  std::span<const std::byte> depth;
  std::span<const std::byte> normals;
  std::span<const std::byte> colour;
};

class GeometryBufferConverter : public TypedConverter<m::GeometryBuffer, GeometryFields> {
 public:
  GeometryBufferConverter()
      : TypedConverter(
            "probeless_msgs/msg/GeometryBuffer",
            ComposeSchema(
                std::string("# A G-buffer seen by a camera (probeless_msgs/GeometryBuffer); planes "
                            "row-major, pixel (x, y) at y * width + x.\n") +
                    std::string(kFullHeaderFields) +
                    "uint32 width\n"
                    "uint32 height\n"
                    "float32[] depth      # width*height, metres along the optical axis (0: none)\n"
                    "float32[] normals    # width*height*3, unit normals in the camera frame\n"
                    "uint8[] colour       # width*height*3, sRGB R, G, B\n",
                {kStdHeader, kTime})) {}

 protected:
  void Write(const m::GeometryBuffer& g, std::span<const std::byte> payload,
             CdrWriter& out) const override {
    const auto depth = m::DepthPlane(g, payload);
    const auto normals = m::NormalsPlane(g, payload);
    const auto colour = m::ColourPlane(g, payload);
    out.Reserve(64 + depth.size_bytes() + normals.size_bytes() + colour.size_bytes());
    WriteFullHeader(out, g.header, ros2_type_);
    out.Write<uint32_t>(g.width);
    out.Write<uint32_t>(g.height);
    out.Sequence(depth);
    out.Sequence(normals);
    out.Sequence(std::span<const uint8_t>(colour));
  }

  GeometryFields Parse(CdrReader& in) const override {
    GeometryFields f;
    ReadFullHeader(in, f.header);
    f.width = in.Read<uint32_t>("width");
    f.height = in.Read<uint32_t>("height");
    const uint64_t pixels = uint64_t{f.width} * f.height;
    if (pixels > kMaxPixels) in.Fail("height", std::to_string(pixels) + " pixels are too many");
    f.depth = in.SequenceBytes<float>("depth");
    if (f.depth.size() != pixels * sizeof(float)) {
      in.Fail("depth", std::to_string(f.depth.size() / sizeof(float)) + " values for " +
                           std::to_string(pixels) + " pixels");
    }
    f.normals = in.SequenceBytes<float>("normals");
    if (f.normals.size() != pixels * 3 * sizeof(float)) {
      in.Fail("normals", std::to_string(f.normals.size() / sizeof(float)) + " values for " +
                             std::to_string(pixels) + " pixels (3 per pixel)");
    }
    f.colour = in.SequenceBytes<uint8_t>("colour");
    if (f.colour.size() != pixels * 3) {
      in.Fail("colour", std::to_string(f.colour.size()) + " bytes for " + std::to_string(pixels) +
                            " pixels (3 per pixel)");
    }
    return f;
  }

  // The planes were checked against the input size, so this is bounded by it.
  size_t SizeOf(const GeometryFields& f) const override {
    return m::GeometryBuffer::MessageBytesFor(f.width, f.height);
  }

  void Fill(const GeometryFields& f, const std::map<std::string, std::string>&,
            m::GeometryBuffer& g, std::span<std::byte> payload) const override {
    g.header = f.header;
    g.Init(f.width, f.height);
    if (!f.depth.empty())
      std::memcpy(payload.data() + g.depth_offset, f.depth.data(), f.depth.size());
    if (!f.normals.empty()) {
      std::memcpy(payload.data() + g.normals_offset, f.normals.data(), f.normals.size());
    }
    if (!f.colour.empty()) {
      std::memcpy(payload.data() + g.colour_offset, f.colour.data(), f.colour.size());
    }
  }

  void Check(const m::GeometryBuffer& g, std::span<const std::byte> payload) const override {
    g.Validate(payload.size());
  }
};

// ---- probeless_msgs/msg/TransferBuffer ----

struct TransferFields {
  m::Header header;
  uint32_t width = 0;
  uint32_t height = 0;
  uint32_t coefficient_count = 0;
  std::span<const std::byte> coefficients;
};

class TransferBufferConverter : public TypedConverter<m::TransferBuffer, TransferFields> {
 public:
  TransferBufferConverter()
      : TypedConverter(
            "probeless_msgs/msg/TransferBuffer",
            ComposeSchema(
                std::string("# Per-pixel SH transfer vectors (probeless_msgs/TransferBuffer).\n") +
                    std::string(kFullHeaderFields) +
                    "uint32 width\n"
                    "uint32 height\n"
                    "uint32 coefficient_count    # 1, 4, 9, 16 or 25\n"
                    "float32[] coefficients      # pixel-major: (y * width + x) * "
                    "coefficient_count + k\n",
                {kStdHeader, kTime})) {}

 protected:
  void Write(const m::TransferBuffer& t, std::span<const std::byte> payload,
             CdrWriter& out) const override {
    const auto coefficients = m::TransferCoefficients(t, payload);
    out.Reserve(64 + coefficients.size_bytes());
    WriteFullHeader(out, t.header, ros2_type_);
    out.Write<uint32_t>(t.width);
    out.Write<uint32_t>(t.height);
    out.Write<uint32_t>(t.coefficient_count);
    out.Sequence(coefficients);
  }

  TransferFields Parse(CdrReader& in) const override {
    TransferFields f;
    ReadFullHeader(in, f.header);
    f.width = in.Read<uint32_t>("width");
    f.height = in.Read<uint32_t>("height");
    f.coefficient_count = in.Read<uint32_t>("coefficient_count");
    if (f.coefficient_count > m::kMaxShCoefficients) {
      in.Fail("coefficient_count", std::to_string(f.coefficient_count) + " exceeds " +
                                       std::to_string(m::kMaxShCoefficients));
    }
    const uint64_t pixels = uint64_t{f.width} * f.height;
    if (pixels > kMaxPixels) in.Fail("height", std::to_string(pixels) + " pixels are too many");
    f.coefficients = in.SequenceBytes<float>("coefficients");
    const uint64_t expected = pixels * f.coefficient_count;
    if (f.coefficients.size() != expected * sizeof(float)) {
      in.Fail("coefficients",
              std::to_string(f.coefficients.size() / sizeof(float)) +
                  " values, width * height * coefficient_count = " + std::to_string(expected));
    }
    return f;
  }

  size_t SizeOf(const TransferFields& f) const override {
    return sizeof(m::TransferBuffer) + f.coefficients.size();
  }

  void Fill(const TransferFields& f, const std::map<std::string, std::string>&,
            m::TransferBuffer& t, std::span<std::byte> payload) const override {
    t.header = f.header;
    t.Init(f.width, f.height, f.coefficient_count);  // throws for a non-square count
    if (!f.coefficients.empty()) {
      std::memcpy(payload.data(), f.coefficients.data(), f.coefficients.size());
    }
  }

  void Check(const m::TransferBuffer& t, std::span<const std::byte> payload) const override {
    t.Validate(payload.size());
  }
};

// ---- probeless_msgs/msg/TrackingStatus ----

struct TrackingFields {
  m::TrackingStatus status;  // every field but the reason text
  std::string reason_text;
};

class TrackingStatusConverter : public TypedConverter<m::TrackingStatus, TrackingFields> {
 public:
  TrackingStatusConverter()
      : TypedConverter(
            "probeless_msgs/msg/TrackingStatus",
            ComposeSchema(
                std::string("# The camera tracker's verdict on one frame "
                            "(probeless_msgs/TrackingStatus, docs/messages.md).\n") +
                    std::string(kFullHeaderFields) +
                    "uint32 state                 # 1 tracked, 2 uncertain, 3 lost\n"
                    "float32 score                # 0..1: from 0.5 tracked, 0 lost\n"
                    "uint32 reasons               # bits: 1 icp, 2 residual, 4 inliers, 8 motion, "
                    "16 degenerate, 32 persistent, 64 relocalising\n"
                    "bool integrated\n"
                    "bool relocalised\n"
                    "float32 rms_m\n"
                    "float32 inlier_fraction\n"
                    "float32 residual_ratio\n"
                    "float32 inlier_ratio\n"
                    "float32 motion_translation_m\n"
                    "float32 motion_rotation_deg\n"
                    "float32 observability\n"
                    "uint64 frames\n"
                    "uint64 tracked_frames\n"
                    "uint64 uncertain_frames\n"
                    "uint64 lost_frames\n"
                    "uint64 relocalisations\n"
                    "string reason_text\n",
                {kStdHeader, kTime})) {}

 protected:
  void Write(const m::TrackingStatus& t, std::span<const std::byte>,
             CdrWriter& out) const override {
    t.Validate();
    WriteFullHeader(out, t.header, ros2_type_);
    out.Write<uint32_t>(static_cast<uint32_t>(t.state));
    out.Write<float>(t.score);
    out.Write<uint32_t>(t.reasons);
    out.Write<uint8_t>(t.integrated);
    out.Write<uint8_t>(t.relocalised);
    for (float v : {t.rms_m, t.inlier_fraction, t.residual_ratio, t.inlier_ratio,
                    t.motion_translation_m, t.motion_rotation_deg, t.observability}) {
      out.Write<float>(v);
    }
    for (uint64_t v : {t.frames, t.tracked_frames, t.uncertain_frames, t.lost_frames,
                       t.relocalisations}) {
      out.Write<uint64_t>(v);
    }
    out.String(t.ReasonText());
  }

  TrackingFields Parse(CdrReader& in) const override {
    TrackingFields f;
    m::TrackingStatus& t = f.status;
    ReadFullHeader(in, t.header);
    t.state = static_cast<m::TrackingStatusState>(in.Read<uint32_t>("state"));
    t.score = in.Read<float>("score");
    t.reasons = in.Read<uint32_t>("reasons");
    t.integrated = in.Read<uint8_t>("integrated");
    t.relocalised = in.Read<uint8_t>("relocalised");
    for (float* v : {&t.rms_m, &t.inlier_fraction, &t.residual_ratio, &t.inlier_ratio,
                     &t.motion_translation_m, &t.motion_rotation_deg, &t.observability}) {
      *v = in.Read<float>("cue");
    }
    t.frames = in.Read<uint64_t>("frames");
    t.tracked_frames = in.Read<uint64_t>("tracked_frames");
    t.uncertain_frames = in.Read<uint64_t>("uncertain_frames");
    t.lost_frames = in.Read<uint64_t>("lost_frames");
    t.relocalisations = in.Read<uint64_t>("relocalisations");
    f.reason_text = in.String("reason_text");
    if (f.reason_text.size() >= m::kTrackingReasonCapacity) {
      in.Fail("reason_text", std::to_string(f.reason_text.size()) + " characters, at most " +
                                 std::to_string(m::kTrackingReasonCapacity - 1) + " fit");
    }
    return f;
  }

  void Fill(const TrackingFields& f, const std::map<std::string, std::string>&,
            m::TrackingStatus& t, std::span<std::byte>) const override {
    t = f.status;
    t.SetReasonText(f.reason_text);
  }

  void Check(const m::TrackingStatus& t, std::span<const std::byte>) const override {
    t.Validate();
  }
};

const ImageConverter kImage;
const CameraInfoConverter kCameraInfo;
const PoseConverter kPoseConverter;
const FaceObservationConverter kFace;
const ShLightConverter kShLight;
const GeometryBufferConverter kGeometry;
const TransferBufferConverter kTransfer;
const TrackingStatusConverter kTracking;
const Ros2Converter* const kConverters[] = {&kImage,    &kCameraInfo, &kPoseConverter,
                                            &kFace,     &kShLight,    &kGeometry,
                                            &kTransfer, &kTracking};

}  // namespace

MessageBuffer::MessageBuffer(size_t bytes) : size_(bytes) {
  if (bytes == 0) return;
  data_.reset(
      static_cast<std::byte*>(::operator new (bytes, std::align_val_t{m::kPayloadAlignment})));
  std::memset(data_.get(), 0, bytes);
}

void MessageBuffer::Shrink(size_t bytes) { size_ = std::min(size_, bytes); }

void MessageBuffer::Free::operator()(std::byte* p) const {
  ::operator delete (p, std::align_val_t{m::kPayloadAlignment});
}

std::map<std::string, std::string> Ros2Converter::ChannelMetadata(
    std::span<const std::byte>) const {
  return {{std::string(kMetadataProbelessType), std::string(probeless_type())},
          {std::string(kMetadataLayoutHash), HexHash(layout_hash())}};
}

std::span<const Ros2Converter* const> AllRos2Converters() { return kConverters; }

const Ros2Converter* FindRos2ConverterByProbelessType(std::string_view probeless_type) {
  for (const Ros2Converter* converter : kConverters) {
    if (converter->probeless_type() == probeless_type) return converter;
  }
  return nullptr;
}

const Ros2Converter* FindRos2ConverterByRos2Type(std::string_view ros2_type) {
  for (const Ros2Converter* converter : kConverters) {
    if (converter->ros2_type() == ros2_type) return converter;
  }
  return nullptr;
}

const Ros2Converter& Ros2ConverterForType(std::string_view probeless_type) {
  const Ros2Converter* converter = FindRos2ConverterByProbelessType(probeless_type);
  if (converter == nullptr) {
    throw CdrError("no ROS 2 conversion for probeless type '" + std::string(probeless_type) + "'");
  }
  return *converter;
}

const std::string& CompressedImageSchemaText() {
  static const std::string text = ComposeSchema(
      "std_msgs/Header header\nstring format\nuint8[] data\n", {kStdHeader, kTime});
  return text;
}

void EncodeCompressedImage(const m::Header& header, std::string_view format,
                           std::span<const std::byte> data, CdrWriter& out) {
  out.Reserve(64 + format.size() + data.size());
  WriteStdHeader(out, header, kRos2CompressedImageType);
  out.String(format);
  out.ByteSequence(data);
}

std::vector<std::byte> EncodeRos2(const Ros2Converter& converter,
                                  std::span<const std::byte> message) {
  CdrWriter writer;
  converter.Encode(message, writer);
  return writer.Take();
}

MessageBuffer DecodeRos2(const Ros2Converter& converter, std::span<const std::byte> cdr,
                         const std::map<std::string, std::string>& channel_metadata) {
  MessageBuffer buffer(converter.DecodedSize(cdr));
  buffer.Shrink(converter.Decode(cdr, channel_metadata, buffer.bytes()));
  return buffer;
}

}  // namespace probeless::log
