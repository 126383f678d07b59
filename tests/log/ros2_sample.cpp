// log_ros2_sample: the C++ side of tests/log/read_with_python_mcap.py.
//
//   log_ros2_sample write DIR
//     writes DIR/sample_none.mcap, DIR/sample_lz4.mcap, DIR/sample_zstd.mcap (the same messages:
//     images of every encoding, camera infos, poses and every probeless_msgs/msg type, through
//     McapWriter and the ROS 2 converters) and DIR/expected.json: every message in log-time order
//     with the values taken from the probeless structs (not from the CDR), for the Python reader
//     to compare against.
//   log_ros2_sample read FILE OUT.json
//     reads FILE (written by Python's mcap-ros2-support) with McapReader, decodes every message
//     with the ROS 2 converters and dumps the probeless field values as JSON.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <map>
#include <span>
#include <string>
#include <vector>

#include "probeless/log/mcap_reader.h"
#include "probeless/log/mcap_writer.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/msgs.h"

namespace {

using namespace probeless;

// ---- minimal JSON output ----

std::string Quote(std::string_view text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      char escaped[8];
      std::snprintf(escaped, sizeof(escaped), "\\u%04x", c);
      out += escaped;
    } else {
      out += c;
    }
  }
  return out + "\"";
}

std::string Number(double value) {
  char text[40];
  std::snprintf(text, sizeof(text), "%.17g", value);
  return text;
}

std::string Number(int64_t value) { return std::to_string(value); }
std::string Number(uint64_t value) { return std::to_string(value); }
std::string Number(uint32_t value) { return std::to_string(value); }

template <class T>
std::string List(std::span<const T> values) {
  std::string out = "[";
  for (size_t i = 0; i < values.size(); ++i) {
    if (i > 0) out += ",";
    if constexpr (std::is_same_v<T, float>) {
      out += Number(static_cast<double>(values[i]));
    } else if constexpr (std::is_same_v<T, bool>) {
      out += values[i] ? "true" : "false";
    } else {
      out += Number(values[i]);
    }
  }
  return out + "]";
}

std::string Hex(std::span<const std::byte> bytes) {
  static const char* digits = "0123456789abcdef";
  std::string out;
  out.reserve(bytes.size() * 2);
  for (std::byte b : bytes) {
    out += digits[static_cast<unsigned>(b) >> 4];
    out += digits[static_cast<unsigned>(b) & 15];
  }
  return out;
}

// An object built field by field.
class Object {
 public:
  Object& Add(std::string_view key, const std::string& json) {
    text_.append(text_.empty() ? "{" : ",");
    text_.append(Quote(key));
    text_.append(":");
    text_.append(json);
    return *this;
  }
  std::string Done() const { return text_.empty() ? "{}" : text_ + "}"; }

 private:
  std::string text_;
};

std::string HeaderJson(const msgs::Header& header) {
  return Object()
      .Add("stamp_ns", Number(header.stamp_ns))
      .Add("stamp_mono_ns", Number(header.stamp_mono_ns))
      .Add("sequence", Number(header.sequence))
      .Add("frame_id", Quote(header.FrameId()))
      .Done();
}

std::string TransformJson(const msgs::RigidTransform& t) {
  const double values[7] = {t.translation.x, t.translation.y, t.translation.z, t.rotation.w,
                            t.rotation.x,    t.rotation.y,    t.rotation.z};
  return Object()
      .Add("translation", List(std::span<const double>(values, 3)))
      .Add("rotation_wxyz", List(std::span<const double>(values + 3, 4)))
      .Done();
}

// The probeless field values of one message (struct + payload) as JSON.
std::string MessageJson(std::string_view type, std::span<const std::byte> bytes) {
  if (type == msgs::Image::kTypeName) {
    const auto image = msgs::ReadMessage<msgs::Image>(bytes);
    return Object()
        .Add("header", HeaderJson(image->header))
        .Add("width", Number(image->width))
        .Add("height", Number(image->height))
        .Add("step", Number(image->step))
        .Add("encoding", Quote(msgs::EncodingName(image->encoding)))
        .Add("data_hex", Quote(Hex(image.payload.first(image->PayloadBytes()))))
        .Done();
  }
  if (type == msgs::CameraInfo::kTypeName) {
    const auto info = msgs::ReadMessage<msgs::CameraInfo>(bytes);
    return Object()
        .Add("header", HeaderJson(info->header))
        .Add("width", Number(info->width))
        .Add("height", Number(info->height))
        .Add("fx", Number(info->fx))
        .Add("fy", Number(info->fy))
        .Add("cx", Number(info->cx))
        .Add("cy", Number(info->cy))
        .Add("distortion_model", Quote(msgs::DistortionModelName(info->distortion_model)))
        .Add("distortion", List(std::span<const double>(info->distortion, info->distortion_count)))
        .Add("depth_scale", Number(info->depth_scale))
        .Done();
  }
  if (type == msgs::Pose::kTypeName) {
    const auto pose = msgs::ReadMessage<msgs::Pose>(bytes);
    return Object()
        .Add("header", HeaderJson(pose->header))
        .Add("parent_frame_id", Quote(pose->ParentFrameId()))
        .Add("child_frame_id", Quote(pose->ChildFrameId()))
        .Add("transform", TransformJson(pose->transform))
        .Done();
  }
  if (type == msgs::FaceObservation::kTypeName) {
    const auto face = msgs::ReadMessage<msgs::FaceObservation>(bytes);
    std::vector<bool> valid_bits;
    for (uint32_t i = 0; i < face->sample_count; ++i) valid_bits.push_back(face->SampleValid(i));
    std::string valid = "[";
    for (size_t i = 0; i < valid_bits.size(); ++i) {
      valid += std::string(i > 0 ? "," : "") + (valid_bits[i] ? "true" : "false");
    }
    valid += "]";
    return Object()
        .Add("header", HeaderJson(face->header))
        .Add("face_detected", face->face_detected != 0 ? "true" : "false")
        .Add("landmarks",
             List(std::span<const float>(&face->landmarks[0][0], face->landmark_count * 2)))
        .Add("head_pose", TransformJson(face->head_pose))
        .Add("quality", Number(static_cast<double>(face->quality)))
        .Add("sample_rgb",
             List(std::span<const float>(&face->sample_rgb[0][0], face->sample_count * 3)))
        .Add("sample_normals",
             List(std::span<const float>(&face->sample_normals[0][0], face->sample_count * 3)))
        .Add("sample_valid", valid)
        .Done();
  }
  if (type == msgs::ShLight::kTypeName) {
    const auto light = msgs::ReadMessage<msgs::ShLight>(bytes);
    return Object()
        .Add("header", HeaderJson(light->header))
        .Add("bands", Number(light->bands))
        .Add("coefficients", List(std::span<const float>(&light->coefficients[0][0],
                                                         light->CoefficientCount() * 3)))
        .Add("dominant_direction", List(std::span<const float>(light->dominant_direction)))
        .Add("intensity", Number(static_cast<double>(light->intensity)))
        .Add("confidence", Number(static_cast<double>(light->confidence)))
        .Add("units", Number(static_cast<uint32_t>(light->units)))
        .Done();
  }
  if (type == msgs::GeometryBuffer::kTypeName) {
    const auto g = msgs::ReadMessage<msgs::GeometryBuffer>(bytes);
    return Object()
        .Add("header", HeaderJson(g->header))
        .Add("width", Number(g->width))
        .Add("height", Number(g->height))
        .Add("depth", List(msgs::DepthPlane(*g, g.payload)))
        .Add("normals", List(msgs::NormalsPlane(*g, g.payload)))
        .Add("colour_hex", Quote(Hex(std::as_bytes(msgs::ColourPlane(*g, g.payload)))))
        .Done();
  }
  if (type == msgs::TransferBuffer::kTypeName) {
    const auto t = msgs::ReadMessage<msgs::TransferBuffer>(bytes);
    return Object()
        .Add("header", HeaderJson(t->header))
        .Add("width", Number(t->width))
        .Add("height", Number(t->height))
        .Add("coefficient_count", Number(t->coefficient_count))
        .Add("coefficients", List(msgs::TransferCoefficients(*t, t.payload)))
        .Done();
  }
  throw log::LogError("no JSON dump for type " + std::string(type));
}

// ---- sample messages ----

uint64_t state = 0x2545F4914F6CDD1Dull;
uint32_t Random() {
  state ^= state << 13;
  state ^= state >> 7;
  state ^= state << 17;
  return static_cast<uint32_t>(state >> 16);
}
float RandomFloat() { return static_cast<float>(Random() % 20001) / 10000.0f - 1.0f; }

void FillHeader(msgs::Header& header, int64_t stamp_ns, uint64_t sequence, const char* frame) {
  header.stamp_ns = stamp_ns;
  header.stamp_mono_ns = 5'000'000'000 + stamp_ns % 1'000'000'000;
  header.sequence = sequence;
  header.SetFrameId(frame);
}

struct Sample {
  std::string topic;
  std::string probeless_type;
  uint64_t log_time = 0;
  uint32_t sequence = 0;
  log::MessageBuffer message;
};

log::MessageBuffer MakeImage(msgs::Encoding encoding, uint32_t width, uint32_t height,
                             uint32_t extra_step, int64_t stamp, uint64_t sequence,
                             const char* frame) {
  const uint32_t step = width * msgs::BytesPerPixel(encoding) + extra_step;
  log::MessageBuffer buffer(sizeof(msgs::Image) + static_cast<size_t>(step) * height);
  auto image = msgs::WriteMessage<msgs::Image>(buffer.bytes());
  FillHeader(image->header, stamp, sequence, frame);
  image->Init(width, height, encoding);
  image->step = step;
  for (std::byte& b : image.payload) b = static_cast<std::byte>(Random() & 0xFF);
  if (encoding == msgs::Encoding::kFloat32) {
    auto values = msgs::ImageChannels<float>(*image, image.payload);
    for (float& v : values) v = RandomFloat() * 3.0f;
  }
  return buffer;
}

std::vector<Sample> MakeSamples() {
  std::vector<Sample> samples;
  const int64_t t0 = 1'700'000'000'123'456'789;
  auto add = [&](std::string topic, std::string_view type, int64_t stamp, uint32_t sequence,
                 log::MessageBuffer message) {
    samples.push_back(Sample{std::move(topic), std::string(type), static_cast<uint64_t>(stamp),
                             sequence, std::move(message)});
  };
  for (uint32_t i = 0; i < 4; ++i) {
    const int64_t stamp = t0 + int64_t{i} * 33'333'333;
    add("/camera/color/image", msgs::Image::kTypeName, stamp, i + 1,
        MakeImage(msgs::Encoding::kRgb8, 40, 30, i == 2 ? 8 : 0, stamp, i + 1, "camera_color"));
    add("/camera/depth/image", msgs::Image::kTypeName, stamp + 1000, i + 1,
        MakeImage(msgs::Encoding::kDepth16, 32, 24, 0, stamp + 1000, i + 1, "camera_depth"));
  }
  const struct {
    msgs::Encoding encoding;
    const char* topic;
  } others[] = {{msgs::Encoding::kBgr8, "/camera/bgr"},
                {msgs::Encoding::kMono8, "/camera/mono8"},
                {msgs::Encoding::kMono16, "/camera/mono16"},
                {msgs::Encoding::kFloat32, "/camera/depth_metres"}};
  int64_t stamp = t0 + 500'000'000;
  for (const auto& other : others) {
    add(other.topic, msgs::Image::kTypeName, stamp, 1,
        MakeImage(other.encoding, 9, 7, 4, stamp, 1, "camera_other"));
    stamp += 1'000'000;
  }

  for (int model = 0; model < 3; ++model) {
    log::MessageBuffer buffer(sizeof(msgs::CameraInfo));
    auto info = msgs::WriteMessage<msgs::CameraInfo>(buffer.bytes());
    FillHeader(info->header, t0 + 2000 + model, 1, model == 0 ? "camera_color" : "camera_depth");
    info->width = 640;
    info->height = 480;
    info->fx = 615.25 + model;
    info->fy = 614.75;
    info->cx = 319.5;
    info->cy = 241.125;
    info->distortion_model = static_cast<msgs::DistortionModel>(model);
    info->distortion_count = msgs::DistortionCoefficientCount(info->distortion_model);
    for (uint32_t i = 0; i < info->distortion_count; ++i)
      info->distortion[i] = 0.01 * (i + 1) - 0.03;
    info->depth_scale = model == 0 ? 0 : 0.001;
    add("/camera/info_" + std::to_string(model), msgs::CameraInfo::kTypeName, t0 + 2000 + model, 1,
        std::move(buffer));
  }

  for (uint32_t i = 0; i < 3; ++i) {
    log::MessageBuffer buffer(sizeof(msgs::Pose));
    auto pose = msgs::WriteMessage<msgs::Pose>(buffer.bytes());
    FillHeader(pose->header, t0 + 3000 + i, i + 1, "world");
    pose->SetParentFrameId("world");
    pose->SetChildFrameId("camera_color");
    pose->transform.translation = {0.5 + i, -1.25, 2.0 / 3.0};
    const double angle = 0.3 * (i + 1);
    pose->transform.rotation = {std::cos(angle / 2), 0, std::sin(angle / 2), 0};
    add("/camera/pose", msgs::Pose::kTypeName, t0 + 3000 + i, i + 1, std::move(buffer));
  }

  {
    log::MessageBuffer buffer(sizeof(msgs::FaceObservation));
    auto face = msgs::WriteMessage<msgs::FaceObservation>(buffer.bytes());
    FillHeader(face->header, t0 + 4000, 7, "camera_color");
    face->face_detected = 1;
    face->landmark_count = 68;
    for (auto& landmark : face->landmarks) {
      landmark[0] = 100.0f + RandomFloat() * 50.0f;
      landmark[1] = 80.0f + RandomFloat() * 40.0f;
    }
    face->head_pose.translation = {0.01, -0.02, 0.6};
    face->head_pose.rotation = {1, 0, 0, 0};
    face->sample_count = 70;
    face->quality = 0.875f;
    for (uint32_t i = 0; i < face->sample_count; ++i) {
      for (int c = 0; c < 3; ++c) {
        face->sample_rgb[i][c] = std::abs(RandomFloat());
        face->sample_normals[i][c] = RandomFloat();
      }
      face->SetSampleValid(i, Random() % 3 != 0);
    }
    add("/face", msgs::FaceObservation::kTypeName, t0 + 4000, 7, std::move(buffer));
  }
  {
    log::MessageBuffer buffer(sizeof(msgs::ShLight));
    auto light = msgs::WriteMessage<msgs::ShLight>(buffer.bytes());
    FillHeader(light->header, t0 + 5000, 3, "camera_color");
    light->bands = 3;
    for (uint32_t i = 0; i < 9; ++i) {
      for (int c = 0; c < 3; ++c) light->coefficients[i][c] = RandomFloat();
    }
    light->dominant_direction[0] = 0.6f;
    light->dominant_direction[1] = -0.8f;
    light->intensity = 2.5f;
    light->confidence = 0.75f;
    light->units = msgs::ShLightUnits::kLinear;
    add("/light", msgs::ShLight::kTypeName, t0 + 5000, 3, std::move(buffer));
  }
  {
    log::MessageBuffer buffer(msgs::GeometryBuffer::MessageBytesFor(5, 3));
    auto g = msgs::WriteMessage<msgs::GeometryBuffer>(buffer.bytes());
    FillHeader(g->header, t0 + 6000, 2, "camera_depth");
    g->Init(5, 3);
    for (float& d : msgs::DepthPlane(*g, g.payload)) d = 0.5f + std::abs(RandomFloat());
    for (float& n : msgs::NormalsPlane(*g, g.payload)) n = RandomFloat();
    for (uint8_t& c : msgs::ColourPlane(*g, g.payload)) c = static_cast<uint8_t>(Random());
    add("/gbuffer", msgs::GeometryBuffer::kTypeName, t0 + 6000, 2, std::move(buffer));
  }
  {
    log::MessageBuffer buffer(msgs::TransferBuffer::MessageBytesFor(4, 2, 9));
    auto t = msgs::WriteMessage<msgs::TransferBuffer>(buffer.bytes());
    FillHeader(t->header, t0 + 7000, 4, "camera_depth");
    t->Init(4, 2, 9);
    for (float& v : msgs::TransferCoefficients(*t, t.payload)) v = RandomFloat();
    add("/transfer", msgs::TransferBuffer::kTypeName, t0 + 7000, 4, std::move(buffer));
  }
  return samples;
}

int Write(const std::string& dir) {
  const std::vector<Sample> samples = MakeSamples();
  for (log::Compression compression :
       {log::Compression::kNone, log::Compression::kLz4, log::Compression::kZstd}) {
    log::WriterOptions options;
    options.compression = compression;
    options.chunk_size = 8 * 1024;  // several chunks
    log::McapWriter writer(
        dir + "/sample_" + std::string(log::CompressionOptionName(compression)) + ".mcap", options);
    std::map<std::string, uint16_t> channels;
    for (const Sample& sample : samples) {
      const log::Ros2Converter& converter = log::Ros2ConverterForType(sample.probeless_type);
      auto [it, added] = channels.try_emplace(sample.topic, 0);
      if (added) {
        const uint16_t schema = writer.AddSchema(converter.ros2_type(), log::kSchemaEncodingRos2Msg,
                                                 converter.schema_text());
        it->second = writer.AddChannel(sample.topic, log::kMessageEncodingCdr, schema,
                                       converter.ChannelMetadata(sample.message.bytes()));
      }
      const std::vector<std::byte> cdr = log::EncodeRos2(converter, sample.message.bytes());
      writer.Write(it->second, sample.sequence, sample.log_time, sample.log_time + 10, cdr);
    }
    writer.Close();
  }

  // Expected values in log-time order (stable: write order for equal times).
  std::vector<const Sample*> order;
  for (const Sample& sample : samples) order.push_back(&sample);
  std::stable_sort(order.begin(), order.end(),
                   [](const Sample* a, const Sample* b) { return a->log_time < b->log_time; });
  std::ofstream out(dir + "/expected.json");
  out << "[\n";
  for (size_t i = 0; i < order.size(); ++i) {
    const Sample& s = *order[i];
    const log::Ros2Converter& converter = log::Ros2ConverterForType(s.probeless_type);
    out << Object()
               .Add("topic", Quote(s.topic))
               .Add("log_time", Number(s.log_time))
               .Add("sequence", Number(s.sequence))
               .Add("probeless_type", Quote(s.probeless_type))
               .Add("schema", Quote(converter.ros2_type()))
               .Add("fields", MessageJson(s.probeless_type, s.message.bytes()))
               .Done()
        << (i + 1 < order.size() ? ",\n" : "\n");
  }
  out << "]\n";
  return out.good() ? 0 : 1;
}

int Read(const std::string& path, const std::string& json_path) {
  log::McapReader reader(path);
  std::ofstream out(json_path);
  out << "[\n";
  log::MessageCursor cursor = reader.Messages();
  log::MessageView message;
  bool first = true;
  while (cursor.Next(message)) {
    if (message.schema == nullptr) throw log::LogError("message without schema");
    const log::Ros2Converter* converter = log::FindRos2ConverterByRos2Type(message.schema->name);
    if (converter == nullptr) throw log::LogError("no converter for " + message.schema->name);
    const log::MessageBuffer decoded =
        log::DecodeRos2(*converter, message.data, message.channel->metadata);
    out << (first ? "" : ",\n")
        << Object()
               .Add("topic", Quote(message.channel->topic))
               .Add("log_time", Number(message.log_time_ns))
               .Add("probeless_type", Quote(converter->probeless_type()))
               .Add("fields", MessageJson(converter->probeless_type(), decoded.bytes()))
               .Done();
    first = false;
  }
  out << "\n]\n";
  return out.good() ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const std::string mode = argc > 1 ? argv[1] : "";
    if (mode == "write" && argc == 3) return Write(argv[2]);
    if (mode == "read" && argc == 4) return Read(argv[2], argv[3]);
    std::fprintf(stderr, "usage: log_ros2_sample write DIR | read FILE OUT.json\n");
    return 2;
  } catch (const std::exception& error) {
    std::fprintf(stderr, "log_ros2_sample: %s\n", error.what());
    return 1;
  }
}
