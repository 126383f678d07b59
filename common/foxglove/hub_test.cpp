#include "probeless/foxglove/hub.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "probeless/msgs/msgs.h"

namespace probeless::foxglove {
namespace {

namespace m = probeless::msgs;
using nlohmann::json;

const std::vector<BusTopic> kTopics = {
    {"/camera/image", std::string(m::Image::kTypeName), m::Image::kLayoutHash},
    {"/scene/light", std::string(m::ShLight::kTypeName), m::ShLight::kLayoutHash}};

HubOptions Options(size_t depth = 4) {
  HubOptions o;
  o.channels.selection.all = true;
  o.limits.max_messages = depth;
  o.parameters = {{"/foxglove_bridge.port", "integer", "8765"}};
  return o;
}

// The JSON of every queued text frame of `client` (data frames and time frames skipped).
std::vector<json> Texts(Hub& hub, uint64_t client) {
  std::vector<json> out;
  while (auto f = hub.Pop(client)) {
    if (f->kind == OutgoingFrame::Kind::kText) out.push_back(json::parse(f->bytes));
  }
  return out;
}

uint32_t ChannelOf(Hub& hub, const std::string& topic) {
  for (const ChannelStats& c : hub.Channels()) {
    if (c.topic == topic) return c.id;
  }
  return 0;
}

std::shared_ptr<EncodedMessage> Message(uint32_t channel, uint64_t t) {
  auto msg = std::make_shared<EncodedMessage>();
  msg->channel_id = channel;
  msg->receive_ns = t;
  msg->payload.assign(16, std::byte{1});
  return msg;
}

TEST(HubTest, ConnectSendsServerInfoAndAdvertise) {
  Hub hub(Options());
  hub.UpdateTopics(kTopics);
  const uint64_t c = hub.Connect("127.0.0.1:5000");
  const std::vector<json> texts = Texts(hub, c);
  ASSERT_EQ(texts.size(), 2u);
  EXPECT_EQ(texts[0]["op"], "serverInfo");
  EXPECT_EQ(texts[0]["capabilities"], json({"time", "parameters"}));
  EXPECT_EQ(texts[1]["op"], "advertise");
  EXPECT_EQ(texts[1]["channels"].size(), 2u);
  // A topic appearing later is advertised to connected clients.
  std::vector<BusTopic> more = kTopics;
  more.push_back({"/render/composite", std::string(m::Image::kTypeName), m::Image::kLayoutHash});
  hub.UpdateTopics(more);
  const std::vector<json> later = Texts(hub, c);
  ASSERT_EQ(later.size(), 1u);
  EXPECT_EQ(later[0]["channels"][0]["topic"], "/render/composite");
}

TEST(HubTest, SubscribeFanOutUnsubscribe) {
  int wakes = 0;
  HubOptions o = Options();
  o.wake = [&](uint64_t) { ++wakes; };
  Hub hub(o);
  hub.UpdateTopics(kTopics);
  const uint64_t a = hub.Connect("a");
  const uint64_t b = hub.Connect("b");
  Texts(hub, a);
  Texts(hub, b);
  const uint32_t image = ChannelOf(hub, "/camera/image");
  const uint64_t g0 = hub.subscription_generation();
  hub.HandleText(a, R"({"op":"subscribe","subscriptions":[{"id":5,"channelId":)" +
                        std::to_string(image) + "}]}");
  EXPECT_GT(hub.subscription_generation(), g0);
  ASSERT_EQ(hub.SubscribedChannels().size(), 1u);
  EXPECT_EQ(hub.SubscribedChannels()[0].bus_topic, "/camera/image");
  EXPECT_TRUE(Texts(hub, a).empty());  // no reply to a good subscribe

  const int before = wakes;
  hub.Publish(Message(image, 77));
  EXPECT_EQ(wakes, before + 1);  // only the subscribed client
  auto f = hub.Pop(a);
  ASSERT_TRUE(f);
  EXPECT_EQ(f->kind, OutgoingFrame::Kind::kMessageData);
  EXPECT_EQ(f->subscription_id, 5u);
  EXPECT_EQ(f->message->receive_ns, 77u);
  EXPECT_FALSE(hub.Pop(b));

  hub.HandleText(a, R"({"op":"unsubscribe","subscriptionIds":[5]})");
  EXPECT_TRUE(hub.SubscribedChannels().empty());
  hub.Publish(Message(image, 78));
  EXPECT_FALSE(hub.Pop(a));
  EXPECT_EQ(hub.Channels()[0].messages + hub.Channels()[1].messages, 2u);
}

TEST(HubTest, BadRequestsGetErrorStatusAndTheClientStays) {
  Hub hub(Options());
  hub.UpdateTopics(kTopics);
  const uint64_t c = hub.Connect("c");
  Texts(hub, c);
  const uint32_t light = ChannelOf(hub, "/scene/light");
  const std::string sub =
      R"({"op":"subscribe","subscriptions":[{"id":1,"channelId":)" + std::to_string(light) + "}]}";
  hub.HandleText(c, "{not json");
  hub.HandleText(c, R"({"op":"subscribe","subscriptions":[{"id":2,"channelId":999}]})");
  hub.HandleText(c, sub);
  hub.HandleText(c, sub);
  hub.HandleText(c, R"({"op":"subscribe","subscriptions":[{"id":3,"channelId":)" +
                        std::to_string(light) + "}]}");
  hub.HandleText(c, R"({"op":"unsubscribe","subscriptionIds":[42]})");
  const std::byte garbage[] = {std::byte{0xde}, std::byte{0xad}};
  hub.HandleBinary(c, garbage);
  const std::vector<json> texts = Texts(hub, c);
  std::vector<std::string> messages;
  for (const json& t : texts) {
    EXPECT_EQ(t["op"], "status");
    EXPECT_EQ(t["level"], 2);
    messages.push_back(t["message"]);
  }
  EXPECT_THAT(
      messages,
      ::testing::ElementsAre(
          "malformed JSON (at byte 3 of 9)", "subscribe: channel 999 is not advertised",
          "subscribe: subscription id 1 is already in use",
          "subscribe: channel " + std::to_string(light) + " is already subscribed (subscription 1)",
          "unsubscribe: subscription 42 does not exist",
          "binary message with opcode 0xde (unknown, 2 bytes) refused"));
  EXPECT_EQ(hub.Clients()[0].errors, 6u);
  // The good subscription survived all of it.
  hub.Publish(Message(light, 1));
  auto f = hub.Pop(c);
  ASSERT_TRUE(f);
  EXPECT_EQ(f->subscription_id, 1u);
  // getParameters answers.
  hub.HandleText(c, R"({"op":"getParameters","parameterNames":[],"id":"x"})");
  const std::vector<json> values = Texts(hub, c);
  ASSERT_EQ(values.size(), 1u);
  EXPECT_EQ(values[0]["op"], "parameterValues");
  EXPECT_EQ(values[0]["parameters"][0]["value"], 8765);
}

TEST(HubTest, StalledClientDropsOnlyItsOwn) {
  HubOptions o = Options(3);
  o.drop_status_period_ns = 1000;
  Hub hub(o);
  hub.UpdateTopics(kTopics);
  const uint64_t fast = hub.Connect("fast");
  const uint64_t stalled = hub.Connect("stalled");
  const uint32_t image = ChannelOf(hub, "/camera/image");
  const std::string sub =
      R"({"op":"subscribe","subscriptions":[{"id":0,"channelId":)" + std::to_string(image) + "}]}";
  hub.HandleText(fast, sub);
  hub.HandleText(stalled, sub);
  Texts(hub, fast);
  uint64_t received = 0;
  uint64_t publish_dropped = 0;  // what Publish returns, for the bus subscriber's count
  for (uint64_t i = 0; i < 100; ++i) {
    publish_dropped += hub.Publish(Message(image, 10'000 * i));
    while (auto f = hub.Pop(fast)) received += f->kind == OutgoingFrame::Kind::kMessageData;
  }
  EXPECT_EQ(received, 100u);
  EXPECT_EQ(publish_dropped, 97u);
  const auto clients = hub.Clients();
  EXPECT_EQ(clients[0].dropped, 0u);
  EXPECT_EQ(clients[1].dropped, 97u);
  EXPECT_EQ(hub.Channels()[0].dropped, 97u);
  // The stalled client gets the newest three, after warning statuses about its drops.
  std::vector<uint64_t> stamps;
  size_t warnings = 0;
  while (auto f = hub.Pop(stalled)) {
    if (f->kind == OutgoingFrame::Kind::kMessageData) stamps.push_back(f->message->receive_ns);
    if (f->kind == OutgoingFrame::Kind::kText && json::parse(f->bytes)["op"] == "status") {
      EXPECT_EQ(json::parse(f->bytes)["level"], 1);
      ++warnings;
    }
  }
  EXPECT_THAT(stamps, ::testing::ElementsAre(970'000, 980'000, 990'000));
  EXPECT_EQ(warnings, 97u);  // one per drop here: the period is 1 us, the stream 10 us apart
}

TEST(HubTest, UnadvertiseDropsSubscriptionsAndDisconnectForgets) {
  Hub hub(Options());
  hub.UpdateTopics(kTopics);
  const uint64_t c = hub.Connect("c");
  const uint32_t light = ChannelOf(hub, "/scene/light");
  hub.HandleText(c, R"({"op":"subscribe","subscriptions":[{"id":9,"channelId":)" +
                        std::to_string(light) + "}]}");
  Texts(hub, c);
  hub.Publish(Message(light, 1));  // queued, then the topic goes
  hub.UpdateTopics(std::vector<BusTopic>{kTopics[0]});
  const std::vector<json> texts = Texts(hub, c);
  ASSERT_EQ(texts.size(), 1u);
  EXPECT_EQ(texts[0],
            json::parse("{\"op\":\"unadvertise\",\"channelIds\":[" + std::to_string(light) + "]}"));
  EXPECT_TRUE(hub.SubscribedChannels().empty());
  hub.Disconnect(c);
  EXPECT_TRUE(hub.Clients().empty());
  EXPECT_FALSE(hub.Pop(c));
  hub.HandleText(c, "{}");  // unknown client: ignored
}

}  // namespace
}  // namespace probeless::foxglove
