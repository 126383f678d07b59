#include "probeless/foxglove/client_queue.h"

#include <gtest/gtest.h>

#include "probeless/foxglove/protocol.h"

namespace probeless::foxglove {
namespace {

std::shared_ptr<const EncodedMessage> Message(uint32_t channel, size_t bytes, uint64_t t) {
  auto m = std::make_shared<EncodedMessage>();
  m->channel_id = channel;
  m->receive_ns = t;
  m->payload.resize(bytes);
  return m;
}

TEST(ClientQueueTest, ControlFirstThenDataInOrder) {
  ClientQueue q({.max_messages = 4});
  q.PushData(1, Message(10, 3, 100));
  q.PushControl("{\"op\":\"status\"}", false);
  q.PushControl(TimeFrame(5), true);
  q.PushData(2, Message(11, 3, 101));
  auto f = q.Pop();
  ASSERT_TRUE(f);
  EXPECT_EQ(f->kind, OutgoingFrame::Kind::kText);
  f = q.Pop();
  EXPECT_EQ(f->kind, OutgoingFrame::Kind::kBinary);
  f = q.Pop();
  EXPECT_EQ(f->kind, OutgoingFrame::Kind::kMessageData);
  EXPECT_EQ(f->subscription_id, 1u);
  EXPECT_EQ(f->message->receive_ns, 100u);
  f = q.Pop();
  EXPECT_EQ(f->subscription_id, 2u);
  EXPECT_FALSE(q.Pop());
  EXPECT_EQ(q.sent(), 2u);
  EXPECT_EQ(q.dropped(), 0u);
}

TEST(ClientQueueTest, DropsOldestByCountAndBytes) {
  ClientQueue q({.max_messages = 3, .max_bytes = 100});
  for (uint64_t i = 0; i < 5; ++i) q.PushData(1, Message(7, 10, i));
  EXPECT_EQ(q.queued_messages(), 3u);
  EXPECT_EQ(q.dropped(), 2u);
  EXPECT_EQ(q.dropped_by_channel().at(7), 2u);
  EXPECT_EQ(q.Pop()->message->receive_ns, 2u);  // the oldest two went
  // A big message pushes out everything before it but is itself kept.
  EXPECT_EQ(q.PushData(1, Message(8, 500, 9)), 2u);
  EXPECT_EQ(q.queued_messages(), 1u);
  EXPECT_EQ(q.queued_bytes(), 500u);
  EXPECT_EQ(q.Pop()->message->receive_ns, 9u);
  EXPECT_EQ(q.dropped(), 4u);
}

TEST(ClientQueueTest, TheCountBoundIsPerSubscription) {
  ClientQueue q({.max_messages = 2});
  for (uint64_t i = 0; i < 6; ++i) q.PushData(1, Message(7, 100, i));  // a fast stream
  q.PushData(2, Message(8, 1, 100));                                   // a slow one
  q.PushData(1, Message(7, 100, 6));
  EXPECT_EQ(q.queued_messages(), 3u);
  EXPECT_EQ(q.dropped_by_channel().at(7), 5u);
  EXPECT_FALSE(q.dropped_by_channel().contains(8));
  EXPECT_EQ(q.Pop()->message->receive_ns, 5u);
  EXPECT_EQ(q.Pop()->message->receive_ns, 100u);  // the slow stream's message survived
  EXPECT_EQ(q.Pop()->message->receive_ns, 6u);
}

TEST(ClientQueueTest, UnsubscribeRemovesWithoutCounting) {
  ClientQueue q({.max_messages = 8});
  q.PushData(1, Message(7, 10, 1));
  q.PushData(2, Message(8, 10, 2));
  q.PushData(1, Message(7, 10, 3));
  q.RemoveSubscription(1);
  EXPECT_EQ(q.queued_messages(), 1u);
  EXPECT_EQ(q.queued_bytes(), 10u);
  EXPECT_EQ(q.dropped(), 0u);
  EXPECT_EQ(q.Pop()->subscription_id, 2u);
}

TEST(ClientQueueTest, ControlOverflowMarksTheClient) {
  ClientQueue q({.max_messages = 1, .max_control = 2});
  q.PushControl("a", false);
  q.PushControl("b", false);
  EXPECT_FALSE(q.Overflowed());
  q.PushControl("c", false);
  EXPECT_TRUE(q.Overflowed());
  EXPECT_EQ(q.Pop()->bytes, "a");
  EXPECT_EQ(q.Pop()->bytes, "b");
  EXPECT_FALSE(q.Pop());
}

TEST(ClientQueueTest, OnlyTheLatestTimeFrameWaits) {
  ClientQueue q({.max_messages = 1, .max_control = 3});
  q.PushControl("a", false);
  for (uint64_t t = 1; t <= 100; ++t) q.PushTime(TimeFrame(t));
  EXPECT_FALSE(q.Overflowed());
  EXPECT_EQ(q.Pop()->bytes, "a");
  auto f = q.Pop();
  ASSERT_TRUE(f);
  EXPECT_EQ(f->bytes, TimeFrame(100));
  EXPECT_FALSE(q.Pop());
  q.PushTime(TimeFrame(101));  // a new one after the queued one was sent
  EXPECT_EQ(q.Pop()->bytes, TimeFrame(101));
}

TEST(ClientQueueTest, BadLimits) {
  try {
    ClientQueue q({.max_messages = 0});
    FAIL();
  } catch (const FoxgloveError& e) {
    EXPECT_STREQ(e.what(), "client queue depth must be >= 1");
  }
}

}  // namespace
}  // namespace probeless::foxglove
