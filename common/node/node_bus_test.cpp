// Integration tests of the node runtime with the real bus: typed publishers and subscribers,
// remapped topics, introspection names, and Spin.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <thread>

#include "probeless/msgs/msgs.h"
#include "probeless/node/growing_publisher.h"
#include "probeless/node/main.h"
#include "probeless/node/node.h"

namespace probeless::node {
namespace {

using namespace std::chrono_literals;

std::vector<std::string> Argv(std::vector<std::string> args) {
  args.insert(args.begin(), "prog");
  return args;
}

// Runs `body` (returning an exit code) in a forked child; its locals (bus objects) are destroyed
// before the child exits, so it leaves nothing in /dev/shm.
template <class F>
int RunInChild(F&& body) {
  const pid_t pid = fork();
  if (pid == 0) _exit(body());
  int status = 0;
  waitpid(pid, &status, 0);
  return status;
}

bus::SubscriberOptions Depth(uint32_t depth) {
  bus::SubscriberOptions options;
  options.queue_depth = depth;
  return options;
}

// Publishes `count` default Pose messages on `pub`; returns their bus sequences.
std::vector<uint64_t> PublishPoses(bus::Publisher& pub, int count) {
  std::vector<uint64_t> sequences;
  for (int i = 0; i < count; ++i) {
    bus::Loan loan = pub.Borrow(sizeof(msgs::Pose));
    msgs::WriteMessage<msgs::Pose>(loan.data());
    sequences.push_back(pub.Publish(std::move(loan)));
  }
  return sequences;
}

// This user's segments of the test's domain currently in /dev/shm.
std::vector<std::string> Segments() {
  const std::string prefix =
      "probeless." + std::to_string(getuid()) + "." + bus::CurrentDomain() + ".";
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator("/dev/shm")) {
    const std::string name = entry.path().filename().string();
    if (name.starts_with(prefix)) names.push_back(name);
  }
  return names;
}

class NodeBusTest : public ::testing::Test {
 protected:
  void SetUp() override {
    bus::CleanDeadSegments();
    ASSERT_TRUE(Segments().empty());
  }
  // Every test (and child process) must leave nothing behind.
  void TearDown() override { EXPECT_EQ(Segments(), std::vector<std::string>{}); }
};

const bus::TopicSnapshot* FindTopic(const std::vector<bus::TopicSnapshot>& topics,
                                    const std::string& name) {
  for (const bus::TopicSnapshot& t : topics) {
    if (t.topic == name) return &t;
  }
  return nullptr;
}
// A snapshot's element must not outlive it: FindTopic(bus::ListTopics(), ...) would dangle.
const bus::TopicSnapshot* FindTopic(std::vector<bus::TopicSnapshot>&& topics,
                                    const std::string& name) = delete;

TEST_F(NodeBusTest, PublisherAndSubscriberTalkWithTypeAndNodeNames) {
  Node talker(Argv({"--ros-args", "-r", "__ns:=/demo"}), "talker");
  Node listener(Argv({"--ros-args", "-r", "__ns:=/demo", "-r", "heard:=chatter"}), "listener");
  bus::PublisherOptions options;
  options.max_message_bytes = msgs::Image::MessageBytesFor(64, 48, msgs::Encoding::kRgb8);
  bus::Publisher pub = talker.CreatePublisher<msgs::Image>("chatter", options);
  bus::Subscriber sub = listener.CreateSubscriber<msgs::Image>("heard", Depth(4));
  EXPECT_EQ(pub.topic(), "/demo/chatter");
  EXPECT_EQ(sub.topic(), "/demo/chatter");
  EXPECT_EQ(pub.SubscriberCount(), 1u);

  const auto topics = bus::ListTopics();
  const bus::TopicSnapshot* topic = FindTopic(topics, "/demo/chatter");
  ASSERT_NE(topic, nullptr);
  EXPECT_EQ(topic->type.name, "probeless_msgs/Image");
  EXPECT_EQ(topic->type.layout_hash, msgs::Image::kLayoutHash);
  ASSERT_EQ(topic->publishers.size(), 1u);
  EXPECT_EQ(topic->publishers[0].node_name, "/demo/talker");
  ASSERT_EQ(topic->subscribers.size(), 1u);
  EXPECT_EQ(topic->subscribers[0].node_name, "/demo/listener");

  for (uint64_t seq = 1; seq <= 3; ++seq) {
    bus::Loan loan = pub.Borrow(msgs::Image::MessageBytesFor(64, 48, msgs::Encoding::kRgb8));
    msgs::WriteView<msgs::Image> out = msgs::WriteMessage<msgs::Image>(loan.data());
    out->header.sequence = seq;
    out->header.SetFrameId("camera");
    out->header.StampNow();
    out->Init(64, 48, msgs::Encoding::kRgb8);
    std::span<uint8_t> pixels = msgs::ImageChannels<uint8_t>(*out, out.payload);
    std::memset(pixels.data(), static_cast<int>(seq), pixels.size());
    pub.Publish(std::move(loan));
  }
  for (uint64_t seq = 1; seq <= 3; ++seq) {
    std::optional<bus::Sample> sample = sub.Take(1s);
    ASSERT_TRUE(sample);
    msgs::ReadView<msgs::Image> in = msgs::ReadMessage<msgs::Image>(sample->data());
    EXPECT_EQ(in->header.sequence, seq);
    EXPECT_EQ(in->header.FrameId(), "camera");
    EXPECT_EQ(in->width, 64u);
    std::span<const uint8_t> pixels = msgs::ImageChannels<uint8_t>(*in, in.payload);
    EXPECT_EQ(pixels.size(), 64u * 48 * 3);
    EXPECT_EQ(pixels.back(), seq);
  }
}

// Publishes one w x h rgb8 image with every byte `value` through `pub`.
void PublishImage(GrowingPublisher<msgs::Image>& pub, uint32_t w, uint32_t h, uint8_t value) {
  bus::Loan loan = pub.Borrow(msgs::Image::MessageBytesFor(w, h, msgs::Encoding::kRgb8));
  msgs::WriteView<msgs::Image> out = msgs::WriteMessage<msgs::Image>(loan.data());
  out->Init(w, h, msgs::Encoding::kRgb8);
  std::span<uint8_t> pixels = msgs::ImageChannels<uint8_t>(*out, out.payload);
  std::memset(pixels.data(), value, pixels.size());
  pub.Publish(std::move(loan));
}

TEST_F(NodeBusTest, GrowingPublisherIsMadeByTheFirstMessageAndGrowsForALargerOne) {
  Node talker(Argv({"--ros-args", "-r", "image:=camera/image"}), "talker");
  Node listener(Argv({}), "listener");
  GrowingPublisher<msgs::Image> pub(talker, "image", {.slot_count = 4});
  EXPECT_FALSE(pub.created());
  const std::vector<bus::TopicSnapshot> before = bus::ListTopics();
  EXPECT_EQ(FindTopic(before, "/camera/image"), nullptr);  // nothing before a message
  bus::Subscriber sub = listener.CreateSubscriber<msgs::Image>("camera/image", Depth(8));
  PublishImage(pub, 32, 24, 1);
  EXPECT_TRUE(pub.created());
  PublishImage(pub, 16, 12, 2);  // smaller: the same publisher
  PublishImage(pub, 64, 48, 3);  // larger: re-created with room for it
  PublishImage(pub, 64, 48, 4);
  std::vector<std::pair<uint32_t, uint8_t>> seen;  // width, first byte
  while (std::optional<bus::Sample> s = sub.Take(200ms)) {
    msgs::ReadView<msgs::Image> in = msgs::ReadMessage<msgs::Image>(s->data());
    seen.emplace_back(in->width, msgs::ImageChannels<uint8_t>(*in, in.payload)[0]);
  }
  const std::vector<std::pair<uint32_t, uint8_t>> expected = {{32, 1}, {16, 2}, {64, 3}, {64, 4}};
  EXPECT_EQ(seen, expected);
  const std::vector<bus::TopicSnapshot> topics = bus::ListTopics();
  const bus::TopicSnapshot* topic = FindTopic(topics, "/camera/image");
  ASSERT_NE(topic, nullptr);
  ASSERT_EQ(topic->publishers.size(), 1u);  // the old one is gone
}

TEST_F(NodeBusTest, FixedSizeTypesNeedNoCapacityAndPayloadTypesDo) {
  Node node(Argv({}), "n");
  bus::Publisher pose = node.CreatePublisher<msgs::Pose>("pose");
  EXPECT_EQ(pose.max_message_bytes(), sizeof(msgs::Pose));
  EXPECT_EQ(pose.topic(), "/pose");
  try {
    node.CreatePublisher<msgs::Image>("image");
    FAIL() << "no error";
  } catch (const NodeError& e) {
    EXPECT_STREQ(e.what(),
                 "node '/n': publisher of probeless_msgs/Image on 'image' needs "
                 "options.max_message_bytes (the type has a variable payload)");
  }
  // A subscriber of another type on the same topic is refused by the bus.
  EXPECT_THROW(node.CreateSubscriber<msgs::ShLight>("pose"), bus::BusError);
  bus::Subscriber ok_sub = node.CreateSubscriber<msgs::Pose>("/pose");
  EXPECT_EQ(ok_sub.PublisherCount(), 1u);
}

TEST_F(NodeBusTest, SpinDeliversToHandlersAndReturnsOnShutdown) {
  const int status = RunInChild([] {
    Node node(Argv({}), "spinner");
    bus::Publisher pub = node.CreatePublisher<msgs::ShLight>("light");
    bus::Subscriber a = node.CreateSubscriber<msgs::ShLight>("light", Depth(16));
    bus::Subscriber b = node.CreateSubscriber<msgs::ShLight>("light", Depth(16));
    std::vector<uint64_t> got_a, got_b;
    std::thread producer([&] {
      for (uint64_t i = 1; i <= 5; ++i) {
        std::this_thread::sleep_for(5ms);
        bus::Loan loan = pub.Borrow(sizeof(msgs::ShLight));
        msgs::WriteMessage<msgs::ShLight>(loan.data())->header.sequence = i;
        pub.Publish(std::move(loan));
      }
    });
    auto record = [](std::vector<uint64_t>& into) {
      return [&into](bus::Sample&& sample) {
        into.push_back(msgs::ReadMessage<msgs::ShLight>(sample.data())->header.sequence);
      };
    };
    std::thread stopper([&] {
      producer.join();
      std::this_thread::sleep_for(100ms);
      kill(getpid(), SIGINT);
    });
    const auto start = std::chrono::steady_clock::now();
    Spin({{&a, record(got_a)}, {&b, record(got_b)}});
    const auto spun = std::chrono::steady_clock::now() - start;
    stopper.join();
    const std::vector<uint64_t> expected = {1, 2, 3, 4, 5};
    if (got_a != expected || got_b != expected) return 40;
    if (spun > 2s) return 41;
    return 0;
  });
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
}

TEST_F(NodeBusTest, IdleSpinReturnsWithinThePollPeriodOfTheSignal) {
  const int status = RunInChild([] {
    Node node(Argv({}), "idle");
    bus::Subscriber sub = node.CreateSubscriber<msgs::Pose>("nothing");
    bus::WaitSet wait_set;
    wait_set.Add(sub);
    std::chrono::steady_clock::time_point signalled;
    std::thread stopper([&] {
      std::this_thread::sleep_for(100ms);
      signalled = std::chrono::steady_clock::now();
      kill(getpid(), SIGINT);
    });
    int calls = 0;
    Spin(wait_set, [&](size_t) { ++calls; });
    const auto returned = std::chrono::steady_clock::now();
    stopper.join();
    if (calls != 0) return 50;
    if (returned - signalled > kShutdownPollPeriod + 80ms) return 51;
    return 0;
  });
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
}

// Node::Spin acknowledges every input on "<fqn>/ack" after its handler returned, naming the input's
// topic, publisher pid and bus sequence (what a lock-step player matches).
TEST_F(NodeBusTest, SpinAcknowledgesEveryInputAfterItsHandler) {
  const int status = RunInChild([] {
    Node node(Argv({"--ros-args", "-r", "__ns:=/lab"}), "worker");
    if (node.AckTopic() != "/lab/worker/ack") return 40;
    bus::Subscriber acks("/lab/worker/ack", msgs::TopicTypeOf<msgs::Ack>(), Depth(16));
    bus::Subscriber input = node.CreateSubscriber<msgs::Pose>("pose", Depth(8));
    bus::Publisher pub("/lab/pose", msgs::TopicTypeOf<msgs::Pose>(), {.max_message_bytes = 1024});
    const std::vector<uint64_t> sent = PublishPoses(pub, 3);
    int handled = 0;
    bool acked_before_handler_returned = false;
    node.Spin({{&input, [&](bus::Sample&&) {
                  ++handled;
                  acked_before_handler_returned |= acks.queued() >= static_cast<uint32_t>(handled);
                  if (handled == 3) RequestShutdown();
                }}});
    if (handled != 3 || acked_before_handler_returned) return 41;
    for (uint64_t sequence : sent) {
      auto sample = acks.Take(1s);
      if (!sample) return 42;
      const auto ack = msgs::ReadMessage<msgs::Ack>(sample->data());
      if (ack->Topic() != "/lab/pose" || ack->publisher_pid != getpid() ||
          ack->publish_sequence != sequence || ack->header.sequence != sequence) {
        return 43;
      }
    }
    return 0;
  });
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
}

// The bad-input rule of Node::Spin: an InputError from a handler rejects that sample only (one
// error line, counted, acknowledged); the node goes on, and a summary line names the count.
TEST_F(NodeBusTest, SpinRejectsABadSampleWithOneLineAndGoesOn) {
  const std::string log_path = "/tmp/probeless_node_bus_test_reject_" + std::to_string(getpid());
  const int status = RunInChild([&] {
    if (!std::freopen(log_path.c_str(), "w", stderr)) return 39;
    Node node(Argv({"--ros-args", "-r", "__ns:=/lab"}), "worker");
    bus::Subscriber acks("/lab/worker/ack", msgs::TopicTypeOf<msgs::Ack>(), Depth(16));
    bus::Subscriber input = node.CreateSubscriber<msgs::Pose>("pose", Depth(8));
    bus::Publisher pub("/lab/pose", msgs::TopicTypeOf<msgs::Pose>(), {.max_message_bytes = 1024});
    PublishPoses(pub, 3);
    int handled = 0;
    node.Spin({{&input, [&](bus::Sample&&) {
                  ++handled;
                  if (handled == 3) RequestShutdown();
                  if (handled == 2) throw msgs::MessageError("pose: 12 bytes, expected 64");
                }}});
    if (handled != 3) return 40;
    if (node.RejectedSamples() != std::map<std::string, uint64_t>{{"/lab/pose", 1}}) return 41;
    for (int i = 0; i < 3; ++i) {
      if (!acks.Take(1s)) return 42;  // the rejected sample is acknowledged too
    }
    return 0;
  });
  std::ifstream file(log_path);
  const std::string log((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  std::remove(log_path.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << log;
  EXPECT_NE(log.find("[error] [/lab/worker] rejected a sample of /lab/pose: pose: 12 bytes, "
                     "expected 64\n"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("[warn] [/lab/worker] /lab/pose: rejected 1 of 3 samples\n"),
            std::string::npos)
      << log;
}

// RejectSample (Spin's rule, and for samples a handler takes itself): the first kLoggedRejections
// per topic are logged, then every kRejectionLogPeriod-th with the count; the line drops a leading
// "<topic>: " of the message and escapes control bytes; the run statistics count them.
TEST_F(NodeBusTest, RejectionsAreLoggedOneByOneThenEveryHundredthAndCounted) {
  const std::string log_path = "/tmp/probeless_node_bus_test_many_" + std::to_string(getpid());
  const int status = RunInChild([&] {
    if (!std::freopen(log_path.c_str(), "w", stderr)) return 39;
    Node node(Argv({}), "worker");
    for (int i = 0; i < 250; ++i) node.RejectSample("/depth", "/depth: bad\nbytes");
    node.RejectSample("/image", "/imagery: kept");
    const std::map<std::string, uint64_t> expected = {{"/depth", 250}, {"/image", 1}};
    return node.RejectedSamples() == expected ? 0 : 40;
  });
  std::ifstream file(log_path);
  const std::string log((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  std::remove(log_path.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << log;
  const std::string line = "[error] [/worker] rejected a sample of /depth: bad\\x0abytes\n";
  size_t lines = 0;
  for (size_t at = log.find(line); at != std::string::npos; at = log.find(line, at + 1)) ++lines;
  EXPECT_EQ(lines, kLoggedRejections) << log;
  EXPECT_NE(log.find("[error] [/worker] rejected a sample of /depth: bad\\x0abytes (100 rejected "
                     "so far; only every 100th is logged)\n"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("(200 rejected so far"), std::string::npos) << log;
  EXPECT_EQ(log.find("(150 rejected so far"), std::string::npos) << log;
  EXPECT_NE(log.find("rejected a sample of /image: /imagery: kept\n"), std::string::npos) << log;
}

// A NodeError or UsageError (configuration), a BusError or any other exception from a handler
// still ends Spin; an unknown parameter override ends it before it starts.
TEST_F(NodeBusTest, SpinPassesConfigurationErrorsOnAndRefusesUnknownOverrides) {
  const int status = RunInChild([] {
    Node node(Argv({}), "worker");
    bus::Subscriber input = node.CreateSubscriber<msgs::Pose>("pose", Depth(8));
    bus::Publisher pub("/pose", msgs::TopicTypeOf<msgs::Pose>(), {.max_message_bytes = 1024});
    PublishPoses(pub, 1);
    try {
      node.Spin({{&input, [](bus::Sample&&) { throw NodeError("bad config"); }}});
      return 40;
    } catch (const NodeError& e) {
      if (std::string(e.what()) != "bad config") return 41;
    }
    PublishPoses(pub, 1);
    try {
      node.Spin({{&input, [](bus::Sample&&) { throw UsageError("bad usage"); }}});
      return 45;
    } catch (const UsageError&) {
    }
    PublishPoses(pub, 1);
    try {
      node.Spin({{&input, [](bus::Sample&&) { throw bus::BusError("bus broke"); }}});
      return 46;
    } catch (const bus::BusError&) {
    }
    PublishPoses(pub, 1);
    try {
      node.Spin({{&input, [](bus::Sample&&) { throw std::runtime_error("a bug"); }}});
      return 47;
    } catch (const std::runtime_error& e) {
      if (std::string(e.what()) != "a bug") return 48;
    }
    if (!node.RejectedSamples().empty()) return 49;
    Node typo(Argv({"--ros-args", "-p", "rat:=3"}), "typo");
    typo.Param("rate", 1.0);
    bool handled = false;
    try {
      typo.Spin({{&input, [&](bus::Sample&&) { handled = true; }}});
      return 42;
    } catch (const NodeError& e) {
      if (std::string(e.what()) !=
          "node '/typo': unknown parameter 'rat' (from -p); did you mean 'rate'?") {
        return 43;
      }
    }
    return handled ? 44 : 0;
  });
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
}

// With $PROBELESS_NODE_STATS, Node::Spin writes <dir>/<node>.json when it returns: the inputs
// handled with their bus counters, rejections and handler times, the outputs published, every
// call.
TEST_F(NodeBusTest, SpinWritesRunStatsWhenAsked) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("node_stats_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const int status = RunInChild([&] {
    setenv("PROBELESS_NODE_STATS", dir.c_str(), 1);
    Node node(Argv({"--ros-args", "-r", "__ns:=/lab"}), "timed");
    bus::Subscriber input = node.CreateSubscriber<msgs::Pose>("pose", Depth(8));
    bus::Publisher out = node.CreatePublisher<msgs::Pose>("out");
    bus::Publisher pub("/lab/pose", msgs::TopicTypeOf<msgs::Pose>(), {.max_message_bytes = 1024});
    PublishPoses(pub, 3);
    int handled = 0;
    node.Spin({{&input, [&](bus::Sample&&) {
                  std::this_thread::sleep_for(2ms);
                  bus::Loan loan = out.Borrow(sizeof(msgs::Pose));
                  msgs::WriteMessage<msgs::Pose>(loan.data());
                  out.Publish(std::move(loan));
                  if (++handled == 3) {
                    RequestShutdown();
                    throw msgs::MessageError("the third is rejected");
                  }
                }}});
    return 0;
  });
  ASSERT_TRUE(WIFEXITED(status));
  ASSERT_EQ(WEXITSTATUS(status), 0);
  std::ifstream file(dir / "lab.timed.json");
  const std::string text((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  std::filesystem::remove_all(dir);
  EXPECT_NE(text.find("\"node\": \"/lab/timed\""), std::string::npos) << text;
  const std::string input =
      "{\"topic\": \"/lab/pose\", \"handled\": 3, \"received\": 3, \"dropped\": 0, \"rejected\": "
      "1, \"handler_ms\": {\"p50\": ";
  const size_t at = text.find(input);
  ASSERT_NE(at, std::string::npos) << text;
  EXPECT_GE(std::stod(text.substr(at + input.size())), 2.0) << text;  // the handler's 2 ms sleep
  EXPECT_NE(text.find("{\"topic\": \"/lab/out\", \"published\": 3}"), std::string::npos) << text;
  EXPECT_NE(text.find("{\"topic\": \"/lab/timed/ack\", \"published\": 3}"), std::string::npos)
      << text;
  EXPECT_NE(text.find("\"calls\": [\n  ["), std::string::npos) << text;
}

}  // namespace
}  // namespace probeless::node
