// The server in-process against a minimal raw-socket WebSocket client (testing/raw_ws_client.h,
// an independent peer), fed by a bus publisher in this process. The Node.js client tests
// (tests/foxglove) use the real Foxglove client libraries.
#include "probeless/foxglove/server.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>

#include "probeless/bus/bus.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/msgs.h"
#include "raw_ws_client.h"

namespace probeless::foxglove {
namespace {

namespace m = probeless::msgs;
using nlohmann::json;
using namespace std::chrono_literals;
using test_client::RawClient;

ServerOptions Options() {
  ServerOptions o;
  o.port = 0;
  o.hub.channels.selection.regex = "^/fox_test/";
  o.hub.parameters = {{"/foxglove_bridge.port", "integer", "0"}};
  o.node_name = "/foxglove_server_test";
  return o;
}

std::string Error(const ServerOptions& o) {
  try {
    Server s(o);
  } catch (const FoxgloveError& e) {
    return e.what();
  }
  return "no error";
}

TEST(ServerTest, OptionErrors) {
  ServerOptions o = Options();
  o.bus_queue_depth = 0;
  EXPECT_EQ(Error(o), "bus queue depth 0 out of range (1..64)");
  o = Options();
  o.jpeg_quality = 101;
  EXPECT_EQ(Error(o), "JPEG quality 101 out of range (1..100)");
  o = Options();
  o.address = "localhost:1";
  EXPECT_EQ(Error(o), "invalid address 'localhost:1'");
  o = Options();
  o.hub.channels.selection = {};
  EXPECT_EQ(Error(o), "no topics selected (expected all, a topic list or a regex)");
  // A port in use.
  Server first(Options());
  o = Options();
  o.port = first.port();
  EXPECT_THAT(Error(o), ::testing::StartsWith(
                            "cannot listen on 127.0.0.1:" + std::to_string(first.port()) + ": "));
}

TEST(ServerTest, HandshakeNeedsAFoxgloveSubprotocol) {
  Server server(Options());
  server.Start();
  RawClient plain(server.port());
  ASSERT_TRUE(plain.connected());
  EXPECT_THAT(plain.Handshake("chat"), ::testing::Not(::testing::HasSubstr(" 101 ")));
  RawClient sdk(server.port());
  const std::string head = sdk.Handshake("foxglove.websocket.v1, foxglove.sdk.v1");
  EXPECT_THAT(head, ::testing::HasSubstr(" 101 "));
  EXPECT_THAT(head, ::testing::HasSubstr("Sec-WebSocket-Protocol: foxglove.sdk.v1"));
  EXPECT_EQ(sdk.NextJson()["op"], "serverInfo");
  server.Stop();
}

TEST(ServerTest, StreamsBusMessagesAsTheRecorderEncodesThem) {
  bus::Publisher pub("/fox_test/light",
                     {std::string(m::ShLight::kTypeName), m::ShLight::kLayoutHash},
                     {.max_message_bytes = sizeof(m::ShLight), .node_name = "test"});
  Server server(Options());
  server.Start();
  RawClient client(server.port());
  ASSERT_THAT(client.Handshake("foxglove.websocket.v1"), ::testing::HasSubstr(" 101 "));
  const json info = client.NextJson();
  EXPECT_EQ(info["op"], "serverInfo");
  const json advertise = client.NextJson();
  ASSERT_EQ(advertise["op"], "advertise");
  ASSERT_EQ(advertise["channels"].size(), 1u);
  EXPECT_EQ(advertise["channels"][0]["topic"], "/fox_test/light");
  EXPECT_EQ(advertise["channels"][0]["schemaName"], "probeless_msgs/msg/ShLight");
  const uint32_t channel = advertise["channels"][0]["id"];
  client.Send(R"({"op":"subscribe","subscriptions":[{"id":42,"channelId":)" +
                  std::to_string(channel) + "}]}",
              1);

  alignas(64) m::ShLight light{};
  light.header.stamp_ns = 1'700'000'000'000'000'000;
  light.header.SetFrameId("camera");
  light.bands = 2;
  light.units = m::ShLightUnits::kLinear;
  light.coefficients[0][0] = 0.5f;
  const std::vector<std::byte> expected =
      log::EncodeRos2(log::Ros2ConverterFor<m::ShLight>(), std::as_bytes(std::span(&light, 1)));
  // Publish until the bridge (subscribed within ~20 ms) forwards one; bounded.
  std::optional<std::string> data;
  for (int i = 0; i < 100 && !data; ++i) {
    pub.PublishCopy(std::as_bytes(std::span(&light, 1)));
    for (int k = 0; k < 20 && !data; ++k) {
      const auto f = client.Next();
      ASSERT_TRUE(f);
      if (f->first == 2 && (*f).second[0] == 0x01) data = f->second;
      if (f->first == 2 && (*f).second[0] == 0x02) break;  // a time frame: publish again
    }
  }
  ASSERT_TRUE(data);
  uint32_t sub = 0;
  std::memcpy(&sub, data->data() + 1, 4);
  EXPECT_EQ(sub, 42u);
  ASSERT_EQ(data->size(), 13 + expected.size());
  EXPECT_EQ(std::memcmp(data->data() + 13, expected.data(), expected.size()), 0);

  // The bridge's bus subscriber shows in introspection.
  bool listed = false;
  for (const bus::TopicSnapshot& t : bus::ListTopics()) {
    for (const bus::SubscriberSnapshot& s : t.subscribers) {
      listed |= t.topic == "/fox_test/light" && s.node_name == "/foxglove_server_test";
    }
  }
  EXPECT_TRUE(listed);

  // Garbage binary: an error status, the connection stays.
  client.Send(std::string("\xde\xad\xbe\xef", 4), 2);
  const json status = client.NextJson();
  EXPECT_EQ(status["op"], "status");
  EXPECT_EQ(status["level"], 2);
  EXPECT_EQ(status["message"], "binary message with opcode 0xde (unknown, 4 bytes) refused");
  client.Send(R"({"op":"getParameters","parameterNames":[],"id":"p"})", 1);
  const json params = client.NextJson();
  EXPECT_EQ(params["op"], "parameterValues");
  EXPECT_EQ(params["id"], "p");

  server.Stop();
  const ServerStats stats = server.Stats();
  ASSERT_EQ(stats.topics.size(), 1u);
  EXPECT_GE(stats.topics[0].received, 1u);
  EXPECT_EQ(stats.topics[0].errors, 0u);
}

}  // namespace
}  // namespace probeless::foxglove
