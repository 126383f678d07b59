// Conversion of probeless messages to and from ROS 2 messages in CDR, with their ros2msg schemas,
// so that recordings open in Foxglove and in ROS 2 tooling (mcap-ros2-support), and replay back
// into probeless messages.
//
// Mapping (details and field-by-field tables in docs/log.md):
//   probeless_msgs/Image          <-> sensor_msgs/msg/Image
//   probeless_msgs/CameraInfo     <-> sensor_msgs/msg/CameraInfo
//   probeless_msgs/Pose           <-> geometry_msgs/msg/PoseStamped
//   probeless_msgs/FaceObservation, ShLight, GeometryBuffer, TransferBuffer, TrackingStatus
//                                 <-> probeless_msgs/msg/<same name> (defined here)
// A probeless Header maps to std_msgs/Header: stamp_ns becomes builtin_interfaces/Time (sec,
// nanosec; the stamp must lie in the int32 seconds range 1901..2038), frame_id the string. The
// standard ROS types cannot carry Header::stamp_mono_ns and Header::sequence (decoded as 0; a
// recorder keeps the sequence in the MCAP Message record), Pose::child_frame_id and
// CameraInfo::depth_scale: the last two travel in channel metadata (ChannelMetadata/Decode). The
// probeless_msgs/msg types carry every field, stamp_mono_ns and sequence included.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/log/cdr.h"
#include "probeless/msgs/header.h"

namespace probeless::log {

// Channel metadata keys written by Converter::ChannelMetadata.
inline constexpr std::string_view kMetadataProbelessType = "probeless.type";
inline constexpr std::string_view kMetadataLayoutHash = "probeless.layout_hash";  // "0x" + 16 hex
inline constexpr std::string_view kMetadataChildFrameId = "probeless.child_frame_id";  // Pose
inline constexpr std::string_view kMetadataDepthScale = "probeless.depth_scale";       // CameraInfo

// One probeless message (struct followed by its payload) in 64-byte aligned memory, as
// msgs::ReadMessage and msgs::WriteMessage require. Move-only.
class MessageBuffer {
 public:
  MessageBuffer() = default;
  // `bytes` zeroed bytes.
  explicit MessageBuffer(size_t bytes);
  std::span<std::byte> bytes() { return {data_.get(), size_}; }
  std::span<const std::byte> bytes() const { return {data_.get(), size_}; }
  size_t size() const { return size_; }
  // Keeps the first `bytes` bytes (never grows).
  void Shrink(size_t bytes);

 private:
  struct Free {
    void operator()(std::byte* p) const;
  };
  std::unique_ptr<std::byte[], Free> data_;
  size_t size_ = 0;
};

// The ROS 2 conversion of one probeless message type. Implementations are stateless and
// thread-safe. Every conversion error throws CdrError (one line naming the type and field).
class Ros2Converter {
 public:
  virtual ~Ros2Converter() = default;

  // The probeless type name and layout hash (msgs::M::kTypeName, msgs::M::kLayoutHash).
  virtual std::string_view probeless_type() const = 0;
  virtual uint64_t layout_hash() const = 0;
  // The ROS 2 type, used as the MCAP schema name ("sensor_msgs/msg/Image").
  virtual std::string_view ros2_type() const = 0;
  // The ros2msg schema: the type's definition, then for each type it uses a line of 80 '=', a
  // line "MSG: pkg/Type" and that type's definition.
  virtual std::string_view schema_text() const = 0;

  // Metadata to store with the recorded channel: probeless.type, probeless.layout_hash, plus the
  // fields the ROS 2 type cannot carry (taken from `message`, the first message recorded).
  virtual std::map<std::string, std::string> ChannelMetadata(
      std::span<const std::byte> message) const;
  // Encodes `message` (the whole bus message: the struct at byte 0, 64-byte aligned, then its
  // payload) into `out` (Reset first). Throws CdrError if the message fails its type's
  // validation.
  virtual void Encode(std::span<const std::byte> message, CdrWriter& out) const = 0;
  // Bytes of the probeless message (struct + payload) that `cdr` decodes to; bounded by the
  // input size plus the struct size. Throws CdrError on malformed input.
  virtual size_t DecodedSize(std::span<const std::byte> cdr) const = 0;
  // Decodes `cdr` into `out` (at least DecodedSize bytes, 64-byte aligned: a MessageBuffer or a
  // bus Loan) and returns the bytes used. `channel_metadata` (as made by ChannelMetadata) supplies
  // the fields the ROS 2 type lacks; missing keys leave them zero. Throws CdrError on malformed
  // input or values the probeless type cannot hold (unknown image encoding, overlong frame id,
  // inconsistent sizes, ...).
  virtual size_t Decode(std::span<const std::byte> cdr,
                        const std::map<std::string, std::string>& channel_metadata,
                        std::span<std::byte> out) const = 0;
};

// The converters of every supported type, and look-ups; null when there is none.
std::span<const Ros2Converter* const> AllRos2Converters();
const Ros2Converter* FindRos2ConverterByProbelessType(std::string_view probeless_type);
const Ros2Converter* FindRos2ConverterByRos2Type(std::string_view ros2_type);
// The converter for probeless type M (e.g. Ros2ConverterFor<msgs::Image>()); throws CdrError if
// the type has none.
const Ros2Converter& Ros2ConverterForType(std::string_view probeless_type);
template <class M>
const Ros2Converter& Ros2ConverterFor() {
  return Ros2ConverterForType(M::kTypeName);
}

// sensor_msgs/msg/CompressedImage, which has no probeless message type: made from an Image by
// whoever compresses it (the foxglove bridge's JPEG channels). Its ROS 2 type name, its ros2msg
// schema (in the format of Ros2Converter::schema_text), and its CDR: `header` as std_msgs/Header
// (as the converters write it), then `format` ("jpeg") and the compressed bytes. Throws CdrError
// if the stamp is outside builtin_interfaces/Time's range.
inline constexpr std::string_view kRos2CompressedImageType = "sensor_msgs/msg/CompressedImage";
const std::string& CompressedImageSchemaText();
void EncodeCompressedImage(const msgs::Header& header, std::string_view format,
                           std::span<const std::byte> data, CdrWriter& out);

// Convenience: the CDR bytes of `message`.
std::vector<std::byte> EncodeRos2(const Ros2Converter& converter,
                                  std::span<const std::byte> message);
// Convenience: decodes into a fresh MessageBuffer of exactly the decoded size.
MessageBuffer DecodeRos2(const Ros2Converter& converter, std::span<const std::byte> cdr,
                         const std::map<std::string, std::string>& channel_metadata = {});

}  // namespace probeless::log
