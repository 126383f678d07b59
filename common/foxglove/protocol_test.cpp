#include "probeless/foxglove/protocol.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstring>
#include <nlohmann/json.hpp>

namespace probeless::foxglove {
namespace {

using nlohmann::json;

TEST(ProtocolTest, SubprotocolPrefersSdkThenWebsocket) {
  const std::vector<std::string> both = {"foxglove.websocket.v1", "foxglove.sdk.v1"};
  EXPECT_EQ(ChooseSubprotocol(both), "foxglove.sdk.v1");
  const std::vector<std::string> old = {"x", "foxglove.websocket.v1"};
  EXPECT_EQ(ChooseSubprotocol(old), "foxglove.websocket.v1");
  const std::vector<std::string> none = {"chat"};
  EXPECT_EQ(ChooseSubprotocol(none), "");
}

TEST(ProtocolTest, ServerMessagesHaveTheSpecFields) {
  const json info =
      json::parse(ServerInfoJson({"bridge", {"time", "parameters"}, {{"k", "v"}}, "42"}));
  EXPECT_EQ(info["op"], "serverInfo");
  EXPECT_EQ(info["name"], "bridge");
  EXPECT_EQ(info["capabilities"], json({"time", "parameters"}));
  EXPECT_EQ(info["metadata"]["k"], "v");
  EXPECT_EQ(info["sessionId"], "42");

  const Channel c{7, "/camera/image", "cdr", "sensor_msgs/msg/Image", "uint32 height\n", "ros2msg"};
  const json adv = json::parse(AdvertiseJson(std::span(&c, 1)));
  EXPECT_EQ(adv["op"], "advertise");
  ASSERT_EQ(adv["channels"].size(), 1u);
  EXPECT_EQ(adv["channels"][0]["id"], 7);
  EXPECT_EQ(adv["channels"][0]["topic"], "/camera/image");
  EXPECT_EQ(adv["channels"][0]["encoding"], "cdr");
  EXPECT_EQ(adv["channels"][0]["schemaName"], "sensor_msgs/msg/Image");
  EXPECT_EQ(adv["channels"][0]["schema"], "uint32 height\n");
  EXPECT_EQ(adv["channels"][0]["schemaEncoding"], "ros2msg");
  EXPECT_EQ(json::parse(AdvertiseJson({}))["channels"], json::array());

  const uint32_t ids[] = {1, 2};
  EXPECT_EQ(json::parse(UnadvertiseJson(ids)),
            json::parse(R"({"op":"unadvertise","channelIds":[1,2]})"));
  const json status = json::parse(StatusJson(StatusLevel::kError, "bad \"thing\""));
  EXPECT_EQ(status["op"], "status");
  EXPECT_EQ(status["level"], 2);
  EXPECT_EQ(status["message"], "bad \"thing\"");
}

TEST(ProtocolTest, ParameterValuesTypedAsDeclared) {
  const std::vector<Parameter> params = {{"/b.port", "integer", "8765"},
                                         {"/b.rate", "double", "0.5"},
                                         {"/b.on", "bool", "true"},
                                         {"/b.name", "string", "[not a list]"},
                                         {"/b.list", "string_array", "[\"a\", \"b\"]"},
                                         {"/b.gains", "double_array", "[1.5, 2]"},
                                         {"/b.odd", "integer", "abc"}};
  const json all = json::parse(ParameterValuesJson(params, {}, std::string("r1")));
  EXPECT_EQ(all["op"], "parameterValues");
  EXPECT_EQ(all["id"], "r1");
  ASSERT_EQ(all["parameters"].size(), params.size());
  EXPECT_EQ(all["parameters"][0], json::parse(R"({"name":"/b.port","value":8765})"));
  EXPECT_EQ(all["parameters"][1],
            json::parse(R"({"name":"/b.rate","value":0.5,"type":"float64"})"));
  EXPECT_EQ(all["parameters"][2]["value"], true);
  EXPECT_EQ(all["parameters"][3]["value"], "[not a list]");
  EXPECT_EQ(all["parameters"][4]["value"], json({"a", "b"}));
  EXPECT_EQ(all["parameters"][5]["type"], "float64_array");
  EXPECT_EQ(all["parameters"][6]["value"], "abc");  // unparsable: sent as text
  const std::vector<std::string> names = {"/b.on", "/nope"};
  const json some = json::parse(ParameterValuesJson(params, names, std::nullopt));
  EXPECT_FALSE(some.contains("id"));
  ASSERT_EQ(some["parameters"].size(), 1u);
  EXPECT_EQ(some["parameters"][0]["name"], "/b.on");
}

TEST(ProtocolTest, BinaryFramesAreLittleEndian) {
  const std::byte payload[] = {std::byte{0xaa}, std::byte{0xbb}};
  const std::string frame = MessageDataFrame(0x01020304, 0x1122334455667788ull, payload);
  ASSERT_EQ(frame.size(), kMessageDataHeaderBytes + 2);
  const unsigned char expected[] = {0x01, 0x04, 0x03, 0x02, 0x01, 0x88, 0x77, 0x66,
                                    0x55, 0x44, 0x33, 0x22, 0x11, 0xaa, 0xbb};
  EXPECT_EQ(std::memcmp(frame.data(), expected, sizeof(expected)), 0);
  const std::string time = TimeFrame(0x0102030405060708ull);
  const unsigned char t[] = {0x02, 0x08, 0x07, 0x06, 0x05, 0x04, 0x03, 0x02, 0x01};
  ASSERT_EQ(time.size(), sizeof(t));
  EXPECT_EQ(std::memcmp(time.data(), t, sizeof(t)), 0);
}

TEST(ProtocolTest, ParsesSupportedRequests) {
  const auto sub = std::get<SubscribeRequest>(ParseClientText(
      R"({"op":"subscribe","subscriptions":[{"id":0,"channelId":3},{"id":4294967295,"channelId":5}]})"));
  ASSERT_EQ(sub.subscriptions.size(), 2u);
  EXPECT_EQ(sub.subscriptions[0].id, 0u);
  EXPECT_EQ(sub.subscriptions[0].channel_id, 3u);
  EXPECT_EQ(sub.subscriptions[1].id, 4294967295u);
  const auto unsub = std::get<UnsubscribeRequest>(
      ParseClientText(R"({"op":"unsubscribe","subscriptionIds":[0,1]})"));
  EXPECT_EQ(unsub.subscription_ids, (std::vector<uint32_t>{0, 1}));
  const auto get = std::get<GetParametersRequest>(
      ParseClientText(R"({"op":"getParameters","parameterNames":["/a"],"id":"q"})"));
  EXPECT_EQ(get.names, std::vector<std::string>{"/a"});
  EXPECT_EQ(get.id, "q");
  EXPECT_FALSE(std::get<GetParametersRequest>(
                   ParseClientText(R"({"op":"getParameters","parameterNames":[]})"))
                   .id.has_value());
}

void ExpectError(std::string_view text, const std::string& message) {
  try {
    ParseClientText(text);
    ADD_FAILURE() << "no error for " << text;
  } catch (const ProtocolError& e) {
    EXPECT_EQ(std::string(e.what()), message) << text;
  }
}

TEST(ProtocolTest, BadClientTextIsOneLineError) {
  ExpectError("{\"op\":", "malformed JSON (at byte 7 of 6)");
  ExpectError("[1,2]", "client message is not a JSON object");
  ExpectError(R"({"op":3})", "client message has no string field 'op'");
  ExpectError(R"({"op":"dance\n"})", "unknown op 'dance?'");
  ExpectError(R"({"op":"subscribe"})", "subscribe: subscriptions is missing");
  ExpectError(R"({"op":"subscribe","subscriptions":{}})",
              "subscribe: subscriptions must be an array");
  ExpectError(R"({"op":"subscribe","subscriptions":[7]})",
              "subscribe: subscriptions[0] must be an object");
  ExpectError(R"({"op":"subscribe","subscriptions":[{"id":1}]})",
              "subscribe: subscriptions[0].channelId is missing");
  ExpectError(R"({"op":"subscribe","subscriptions":[{"id":-1,"channelId":2}]})",
              "subscribe: subscriptions[0].id must be an unsigned 32-bit integer");
  ExpectError(R"({"op":"subscribe","subscriptions":[{"id":1,"channelId":4294967296}]})",
              "subscribe: subscriptions[0].channelId must be an unsigned 32-bit integer");
  ExpectError(R"({"op":"subscribe","subscriptions":[{"id":1.5,"channelId":2}]})",
              "subscribe: subscriptions[0].id must be an unsigned 32-bit integer");
  ExpectError(R"({"op":"unsubscribe","subscriptionIds":["a"]})",
              "unsubscribe: subscriptionIds[0] must be an unsigned 32-bit integer");
  ExpectError(R"({"op":"getParameters","parameterNames":[1]})",
              "getParameters: parameterNames[0] must be a string");
  ExpectError(R"({"op":"getParameters","parameterNames":[],"id":5})",
              "getParameters: id must be a string");
  ExpectError(R"({"op":"setParameters","parameters":[]})",
              "op 'setParameters' is refused: parameters are read-only on this server");
  ExpectError(R"({"op":"advertise","channels":[]})",
              "op 'advertise' needs capability 'clientPublish', which this server does not offer");
}

TEST(ProtocolTest, BinaryClientMessagesAreRefused) {
  const std::byte publish[] = {std::byte{0x01}, std::byte{0}, std::byte{0}, std::byte{0},
                               std::byte{0}};
  const std::byte garbage[] = {std::byte{0x7f}, std::byte{0x13}};
  auto message = [](std::span<const std::byte> data) {
    try {
      RejectClientBinary(data);
    } catch (const ProtocolError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(message(publish),
            "binary message with opcode 0x01 (client message data, 5 bytes) refused: needs "
            "capability 'clientPublish', which this server does not offer");
  EXPECT_EQ(message(garbage), "binary message with opcode 0x7f (unknown, 2 bytes) refused");
  EXPECT_EQ(message({}), "empty binary message");
}

}  // namespace
}  // namespace probeless::foxglove
