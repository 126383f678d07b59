// The Foxglove WebSocket protocol (subprotocols foxglove.sdk.v1 and foxglove.websocket.v1, one
// message set): the JSON messages a server sends, the binary frames, and the parsing of what a
// client sends. No I/O here; the server (server.h) moves these strings over a WebSocket.
//
// Server → client: serverInfo, status, advertise, unadvertise, parameterValues (JSON text) and
// messageData (opcode 0x01, uint32 subscription id, uint64 receive time ns, payload) and time
// (opcode 0x02, uint64 ns) as binary frames, integers little-endian.
// Client → server, as this server supports them: subscribe, unsubscribe, getParameters. Every
// other known op needs a capability this server does not offer (clientPublish, parameter
// writes and updates, services, connection graph, assets); parsing it throws a ProtocolError
// naming it, as it does for malformed JSON, missing or mistyped fields and binary messages.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "probeless/error/error.h"

namespace probeless::foxglove {

// Bad configuration of the bridge (options, topic selection); what() is one line.
class FoxgloveError : public InputError {
 public:
  using InputError::InputError;
};

// A client message the server cannot accept; what() is one line, sent back as an error status,
// e.g. "subscribe: subscriptions[1].channelId must be an unsigned 32-bit integer".
class ProtocolError : public FoxgloveError {
 public:
  using FoxgloveError::FoxgloveError;
};

inline constexpr std::string_view kSubprotocolSdk = "foxglove.sdk.v1";
inline constexpr std::string_view kSubprotocolWebsocket = "foxglove.websocket.v1";

// The subprotocol to accept from those a client offers in its handshake: foxglove.sdk.v1 if
// offered, else foxglove.websocket.v1, else empty (the handshake is then refused).
std::string_view ChooseSubprotocol(std::span<const std::string> offered);

enum class StatusLevel : int { kInfo = 0, kWarning = 1, kError = 2 };

// One advertised channel.
struct Channel {
  uint32_t id = 0;
  std::string topic;            // the bus topic (or its JPEG variant "<topic>/compressed")
  std::string encoding;         // "cdr"
  std::string schema_name;      // "sensor_msgs/msg/Image"
  std::string schema;           // ros2msg text
  std::string schema_encoding;  // "ros2msg"
};

// A read-only parameter as the node runtime describes it (node::ParamInfo): type "bool",
// "integer", "double", "string" or "<one of those>_array" / "empty_array", value in YAML/JSON
// flow syntax ("30", "0.5", "rgb8", "[1, 2]", "[\"a\", \"b\"]").
struct Parameter {
  std::string name;
  std::string type;
  std::string value;
};

struct ServerInfo {
  std::string name;
  std::vector<std::string> capabilities;  // e.g. "time", "parameters"
  std::map<std::string, std::string> metadata;
  std::string session_id;
};

// The JSON texts of the server messages.
std::string ServerInfoJson(const ServerInfo& info);
std::string AdvertiseJson(std::span<const Channel> channels);
std::string UnadvertiseJson(std::span<const uint32_t> channel_ids);
std::string StatusJson(StatusLevel level, std::string_view message);
// parameterValues with the parameters whose names are in `names` (all when empty), in the order
// given; values typed as their `type` says (float64 and float64_array marked as such); a value
// that does not parse as its type is sent as a string. `id` is echoed when set.
std::string ParameterValuesJson(std::span<const Parameter> parameters,
                                std::span<const std::string> names,
                                const std::optional<std::string>& id);

// Binary server frames.
inline constexpr uint8_t kOpMessageData = 0x01;
inline constexpr uint8_t kOpTime = 0x02;
inline constexpr size_t kMessageDataHeaderBytes = 13;  // opcode, subscription id, timestamp
// The 13-byte header of a messageData frame (the payload follows it).
std::string MessageDataHeader(uint32_t subscription_id, uint64_t receive_ns);
// A whole messageData frame (header + payload).
std::string MessageDataFrame(uint32_t subscription_id, uint64_t receive_ns,
                             std::span<const std::byte> payload);
// A time frame.
std::string TimeFrame(uint64_t timestamp_ns);

// Client requests this server handles.
struct Subscription {
  uint32_t id = 0;          // chosen by the client
  uint32_t channel_id = 0;  // an advertised channel
};
struct SubscribeRequest {
  std::vector<Subscription> subscriptions;
};
struct UnsubscribeRequest {
  std::vector<uint32_t> subscription_ids;
};
struct GetParametersRequest {
  std::vector<std::string> names;  // empty: all
  std::optional<std::string> id;
};
using ClientRequest = std::variant<SubscribeRequest, UnsubscribeRequest, GetParametersRequest>;

// Parses a client text message. Throws ProtocolError (one line) for malformed JSON, a message
// that is not an object or has no string "op", an unknown op, an op needing a capability this
// server does not offer, or missing/mistyped fields.
ClientRequest ParseClientText(std::string_view text);
// Every client binary message (client publishing 0x01, service calls 0x02, anything else) needs
// a capability this server does not offer: always throws ProtocolError naming the opcode.
[[noreturn]] void RejectClientBinary(std::span<const std::byte> data);

}  // namespace probeless::foxglove
