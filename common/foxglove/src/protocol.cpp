#include "probeless/foxglove/protocol.h"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>

namespace probeless::foxglove {
namespace {

using nlohmann::json;

// Ops of the protocol this server declines, with the capability each needs.
struct Declined {
  std::string_view op;
  std::string_view reason;
};
constexpr Declined kDeclinedOps[] = {
    {"advertise", "needs capability 'clientPublish', which this server does not offer"},
    {"unadvertise", "needs capability 'clientPublish', which this server does not offer"},
    {"setParameters", "is refused: parameters are read-only on this server"},
    {"subscribeParameterUpdates",
     "needs capability 'parametersSubscribe', which this server does not offer"},
    {"unsubscribeParameterUpdates",
     "needs capability 'parametersSubscribe', which this server does not offer"},
    {"subscribeConnectionGraph",
     "needs capability 'connectionGraph', which this server does not offer"},
    {"unsubscribeConnectionGraph",
     "needs capability 'connectionGraph', which this server does not offer"},
    {"fetchAsset", "needs capability 'assets', which this server does not offer"},
};

[[noreturn]] void Fail(std::string_view op, const std::string& problem) {
  throw ProtocolError(std::string(op) + ": " + problem);
}

// JSON parses non-negative integers as unsigned, negative ones as signed, others as floats.
bool IsU32(const json& v) {
  return v.is_number_unsigned() && v.get<uint64_t>() <= std::numeric_limits<uint32_t>::max();
}

uint32_t ReadU32(const json& object, std::string_view op, const std::string& path,
                 const char* key) {
  const auto it = object.find(key);
  if (it == object.end()) Fail(op, path + key + " is missing");
  if (!IsU32(*it)) {
    Fail(op, path + key + " must be an unsigned 32-bit integer");
  }
  return static_cast<uint32_t>(it->get<uint64_t>());
}

const json& RequireArray(const json& message, std::string_view op, const char* key) {
  const auto it = message.find(key);
  if (it == message.end()) Fail(op, std::string(key) + " is missing");
  if (!it->is_array()) Fail(op, std::string(key) + " must be an array");
  return *it;
}

// `text` with bytes outside printable ASCII as '?', at most 64 characters (for error lines).
std::string Printable(std::string_view text) {
  std::string out(text.substr(0, 64));
  for (char& c : out) {
    if (c < 0x20 || c > 0x7e) c = '?';
  }
  return out;
}

// A parameter value as its declared type; nullopt if it does not parse so.
std::optional<json> TypedValue(const Parameter& p) {
  try {
    if (p.type == "string") return json(p.value);
    json value = json::parse(p.value);
    if (p.type == "bool" && value.is_boolean()) return value;
    if (p.type == "integer" && value.is_number_integer()) return value;
    if (p.type == "double" && value.is_number()) return value;
    if (p.type.ends_with("_array") && value.is_array()) return value;
  } catch (const json::exception&) {
  }
  return std::nullopt;
}

}  // namespace

std::string_view ChooseSubprotocol(std::span<const std::string> offered) {
  for (std::string_view wanted : {kSubprotocolSdk, kSubprotocolWebsocket}) {
    if (std::find(offered.begin(), offered.end(), wanted) != offered.end()) return wanted;
  }
  return {};
}

std::string ServerInfoJson(const ServerInfo& info) {
  json message = {{"op", "serverInfo"},
                  {"name", info.name},
                  {"capabilities", info.capabilities},
                  {"supportedEncodings", json::array()},
                  {"metadata", info.metadata},
                  {"sessionId", info.session_id}};
  return message.dump();
}

std::string AdvertiseJson(std::span<const Channel> channels) {
  json list = json::array();
  for (const Channel& c : channels) {
    list.push_back({{"id", c.id},
                    {"topic", c.topic},
                    {"encoding", c.encoding},
                    {"schemaName", c.schema_name},
                    {"schema", c.schema},
                    {"schemaEncoding", c.schema_encoding}});
  }
  return json{{"op", "advertise"}, {"channels", list}}.dump();
}

std::string UnadvertiseJson(std::span<const uint32_t> channel_ids) {
  return json{{"op", "unadvertise"},
              {"channelIds", std::vector<uint32_t>(channel_ids.begin(), channel_ids.end())}}
      .dump();
}

std::string StatusJson(StatusLevel level, std::string_view message) {
  return json{{"op", "status"}, {"level", static_cast<int>(level)}, {"message", message}}.dump(
      -1, ' ', false, json::error_handler_t::replace);
}

std::string ParameterValuesJson(std::span<const Parameter> parameters,
                                std::span<const std::string> names,
                                const std::optional<std::string>& id) {
  json list = json::array();
  auto add = [&list](const Parameter& p) {
    json entry = {{"name", p.name}};
    const std::optional<json> value = TypedValue(p);
    entry["value"] = value ? *value : json(p.value);
    if (value && p.type == "double") entry["type"] = "float64";
    if (value && p.type == "double_array") entry["type"] = "float64_array";
    list.push_back(std::move(entry));
  };
  if (names.empty()) {
    for (const Parameter& p : parameters) add(p);
  } else {
    for (const std::string& name : names) {
      for (const Parameter& p : parameters) {
        if (p.name == name) add(p);
      }
    }
  }
  json message = {{"op", "parameterValues"}, {"parameters", list}};
  if (id) message["id"] = *id;
  return message.dump(-1, ' ', false, json::error_handler_t::replace);
}

std::string MessageDataHeader(uint32_t subscription_id, uint64_t receive_ns) {
  std::string header(kMessageDataHeaderBytes, '\0');
  header[0] = static_cast<char>(kOpMessageData);
  // Little-endian on the wire, as on every platform this builds for (x86-64).
  std::memcpy(header.data() + 1, &subscription_id, 4);
  std::memcpy(header.data() + 5, &receive_ns, 8);
  return header;
}

std::string MessageDataFrame(uint32_t subscription_id, uint64_t receive_ns,
                             std::span<const std::byte> payload) {
  std::string frame = MessageDataHeader(subscription_id, receive_ns);
  frame.append(reinterpret_cast<const char*>(payload.data()), payload.size());
  return frame;
}

std::string TimeFrame(uint64_t timestamp_ns) {
  std::string frame(9, '\0');
  frame[0] = static_cast<char>(kOpTime);
  std::memcpy(frame.data() + 1, &timestamp_ns, 8);
  return frame;
}

ClientRequest ParseClientText(std::string_view text) {
  json message;
  try {
    message = json::parse(text);
  } catch (const json::parse_error& e) {
    throw ProtocolError("malformed JSON (at byte " + std::to_string(e.byte) + " of " +
                        std::to_string(text.size()) + ")");
  }
  if (!message.is_object()) throw ProtocolError("client message is not a JSON object");
  const auto op_it = message.find("op");
  if (op_it == message.end() || !op_it->is_string()) {
    throw ProtocolError("client message has no string field 'op'");
  }
  const std::string op = op_it->get<std::string>();
  if (op == "subscribe") {
    SubscribeRequest request;
    const json& list = RequireArray(message, op, "subscriptions");
    for (size_t i = 0; i < list.size(); ++i) {
      const std::string path = "subscriptions[" + std::to_string(i) + "].";
      if (!list[i].is_object())
        Fail(op, "subscriptions[" + std::to_string(i) + "] must be an object");
      request.subscriptions.push_back(
          {ReadU32(list[i], op, path, "id"), ReadU32(list[i], op, path, "channelId")});
    }
    return request;
  }
  if (op == "unsubscribe") {
    UnsubscribeRequest request;
    const json& list = RequireArray(message, op, "subscriptionIds");
    for (size_t i = 0; i < list.size(); ++i) {
      const json& v = list[i];
      if (!IsU32(v)) {
        Fail(op, "subscriptionIds[" + std::to_string(i) + "] must be an unsigned 32-bit integer");
      }
      request.subscription_ids.push_back(static_cast<uint32_t>(v.get<uint64_t>()));
    }
    return request;
  }
  if (op == "getParameters") {
    GetParametersRequest request;
    const json& list = RequireArray(message, op, "parameterNames");
    for (size_t i = 0; i < list.size(); ++i) {
      if (!list[i].is_string()) {
        Fail(op, "parameterNames[" + std::to_string(i) + "] must be a string");
      }
      request.names.push_back(list[i].get<std::string>());
    }
    if (const auto id = message.find("id"); id != message.end()) {
      if (!id->is_string()) Fail(op, "id must be a string");
      request.id = id->get<std::string>();
    }
    return request;
  }
  for (const Declined& d : kDeclinedOps) {
    if (op == d.op) throw ProtocolError("op '" + op + "' " + std::string(d.reason));
  }
  throw ProtocolError("unknown op '" + Printable(op) + "'");
}

void RejectClientBinary(std::span<const std::byte> data) {
  if (data.empty()) throw ProtocolError("empty binary message");
  const unsigned opcode = std::to_integer<unsigned>(data[0]);
  char hex[8];
  std::snprintf(hex, sizeof(hex), "0x%02x", opcode);
  const std::string what = opcode == 0x01   ? "client message data"
                           : opcode == 0x02 ? "a service call request"
                                            : "unknown";
  const std::string needs = opcode == 0x01   ? ": needs capability 'clientPublish'"
                            : opcode == 0x02 ? ": needs capability 'services'"
                                             : "";
  throw ProtocolError("binary message with opcode " + std::string(hex) + " (" + what + ", " +
                      std::to_string(data.size()) + " bytes) refused" + needs +
                      (needs.empty() ? "" : ", which this server does not offer"));
}

}  // namespace probeless::foxglove
