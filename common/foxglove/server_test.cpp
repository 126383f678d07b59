// The server in-process against a minimal raw-socket WebSocket client written here (an
// independent peer: the handshake and RFC 6455 frames by hand, client frames masked), fed by a
// bus publisher in this process. The Node.js client tests (tests/foxglove) use the real
// Foxglove client libraries.
#include "probeless/foxglove/server.h"

#include <arpa/inet.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>

#include "probeless/bus/bus.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/msgs.h"

namespace probeless::foxglove {
namespace {

namespace m = probeless::msgs;
using nlohmann::json;
using namespace std::chrono_literals;

class RawClient {
 public:
  explicit RawClient(uint16_t port) {
    fd_ = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0;
  }
  ~RawClient() { close(fd_); }

  // Sends the upgrade request; returns the HTTP response head.
  std::string Handshake(const std::string& protocols) {
    std::string request =
        "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n";
    if (!protocols.empty()) request += "Sec-WebSocket-Protocol: " + protocols + "\r\n";
    request += "\r\n";
    Write(request);
    std::string head;
    while (head.find("\r\n\r\n") == std::string::npos) {
      const std::optional<std::string> b = Read(1);
      if (!b) break;
      head += *b;
    }
    return head;
  }

  // A masked client frame (opcode 1 text, 2 binary).
  void Send(const std::string& payload, int opcode) {
    std::string frame(1, static_cast<char>(0x80 | opcode));
    const unsigned char mask[4] = {0x12, 0x34, 0x56, 0x78};
    if (payload.size() < 126) {
      frame += static_cast<char>(0x80 | payload.size());
    } else {
      frame += static_cast<char>(0x80 | 126);
      frame += static_cast<char>(payload.size() >> 8);
      frame += static_cast<char>(payload.size() & 0xff);
    }
    frame.append(reinterpret_cast<const char*>(mask), 4);
    for (size_t i = 0; i < payload.size(); ++i)
      frame += static_cast<char>(payload[i] ^ mask[i % 4]);
    Write(frame);
  }

  // The next server frame: {opcode, payload}; nullopt on timeout or close.
  std::optional<std::pair<int, std::string>> Next() {
    const auto head = Read(2);
    if (!head) return std::nullopt;
    const int opcode = (*head)[0] & 0x0f;
    uint64_t length = (*head)[1] & 0x7f;
    if (length == 126 || length == 127) {
      const auto ext = Read(length == 126 ? 2 : 8);
      if (!ext) return std::nullopt;
      length = 0;
      for (unsigned char c : *ext) length = (length << 8) | c;
    }
    const auto payload = Read(length);
    if (!payload) return std::nullopt;
    return std::make_pair(opcode, *payload);
  }

  // The next text frame's JSON (skipping binary time frames).
  json NextJson() {
    for (int i = 0; i < 1000; ++i) {
      const auto f = Next();
      if (!f) return json();
      if (f->first == 1) return json::parse(f->second);
    }
    return json();
  }

  bool connected() const { return connected_; }

 private:
  void Write(const std::string& bytes) {
    size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::send(fd_, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
      if (n <= 0) return;
      done += static_cast<size_t>(n);
    }
  }
  std::optional<std::string> Read(size_t n) {
    std::string out(n, '\0');
    size_t done = 0;
    while (done < n) {
      pollfd p{fd_, POLLIN, 0};
      if (poll(&p, 1, 5000) <= 0) return std::nullopt;
      const ssize_t r = ::recv(fd_, out.data() + done, n - done, 0);
      if (r <= 0) return std::nullopt;
      done += static_cast<size_t>(r);
    }
    return out;
  }
  int fd_ = -1;
  bool connected_ = false;
};

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
