// Two probeless graphs (two PROBELESS_DOMAIN values) connected only by two dds_bridge processes
// over Cyclone DDS on loopback (127.0.0.1, unicast discovery, no multicast): frames arrive intact
// and in order, and every frame that does not arrive is one a bridge or the bus counted as dropped;
// a plain Cyclone subscriber with idlc-generated sensor_msgs/msg/Image types decodes our images;
// killing a bridge and restarting it resumes the flow.
#include <dds/dds.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "Image.h"  // idlc-generated from Image.idl
#include "probeless/bus/bus.h"
#include "probeless/dds_bridge/bridge.h"
#include "probeless/msgs/image.h"
#include "probeless/msgs/layout.h"
#include "probeless/testing/testing.h"

namespace {

using namespace probeless;
using namespace std::chrono_literals;
using probeless::testing::Process;

constexpr uint32_t kWidth = 640, kHeight = 480;
constexpr int64_t kBaseStamp = 1'700'000'000'000'000'000;  // ns since the epoch

int DdsDomain(int offset) { return 20 + (getpid() % 50) * 4 + offset; }

std::string BusDomain(const std::string& test, char side) {
  return "dds" + std::to_string(getpid()) + test + side;
}

void UseBusDomain(const std::string& domain) { setenv("PROBELESS_DOMAIN", domain.c_str(), 1); }

// Declared before the processes and bus endpoints of a test, so it runs last: removes what killed
// bridges left in the test's bus domains.
struct CleanBusDomains {
  std::vector<std::string> domains;
  ~CleanBusDomains() {
    for (const std::string& d : domains) bus::CleanDeadSegments(d);
  }
};

uint8_t Pixel(uint32_t index, size_t j) {
  return static_cast<uint8_t>(index * 31 + j * 7 + (j >> 11));
}

void PublishFrame(bus::Publisher& pub, uint32_t index) {
  const size_t bytes = msgs::Image::MessageBytesFor(kWidth, kHeight, msgs::Encoding::kRgb8);
  bus::Loan loan = pub.Borrow(bytes);
  auto* image = new (loan.data().data()) msgs::Image();
  image->header.stamp_ns = kBaseStamp + int64_t{index} * 1'000'000;
  image->header.sequence = index + 1;
  image->header.SetFrameId("camera_optical");
  image->Init(kWidth, kHeight, msgs::Encoding::kRgb8);
  std::byte* payload = loan.data().data() + sizeof(msgs::Image);
  for (size_t j = 0; j < image->PayloadBytes(); ++j) payload[j] = std::byte{Pixel(index, j)};
  pub.Publish(std::move(loan));
}

bus::Publisher MakeImagePublisher() {
  bus::PublisherOptions o;
  o.max_message_bytes = msgs::Image::MessageBytesFor(kWidth, kHeight, msgs::Encoding::kRgb8);
  // More slots than the sending bridge's bus queue holds (kBridgeQueueDepth): a full queue of
  // that bridge never makes Borrow steal from it.
  o.slot_count = 80;
  o.node_name = "/dds_test_camera";
  return bus::Publisher("/camera/image", msgs::TopicTypeOf<msgs::Image>(), o);
}

bus::Subscriber MakeImageSubscriber() {
  bus::SubscriberOptions o;
  o.queue_depth = 64;
  o.node_name = "/dds_test_viewer";
  return bus::Subscriber("/camera/image", msgs::TopicTypeOf<msgs::Image>(), o);
}

// Index of a received frame; -1 (and a test failure) if it is not intact.
int64_t CheckFrame(const bus::Sample& s) {
  const auto* image = s.As<msgs::Image>();
  const int64_t index = (image->header.stamp_ns - kBaseStamp) / 1'000'000;
  EXPECT_EQ(image->width, kWidth);
  EXPECT_EQ(image->height, kHeight);
  EXPECT_EQ(image->encoding, msgs::Encoding::kRgb8);
  EXPECT_EQ(image->header.FrameId(), "camera_optical");
  EXPECT_EQ(s.data().size(), msgs::Image::MessageBytesFor(kWidth, kHeight, msgs::Encoding::kRgb8));
  const std::byte* payload = s.data().data() + sizeof(msgs::Image);
  for (size_t j = 0; j < image->PayloadBytes(); ++j) {
    if (payload[j] != std::byte{Pixel(static_cast<uint32_t>(index), j)}) {
      ADD_FAILURE() << "frame " << index << " corrupt at byte " << j;
      return -1;
    }
  }
  return index;
}

// The bridges of the two-graph tests: reliable DDS with a history longer than any stream of a
// test (keep-last never overwrites a frame there, which DDS would not count), and a sending-side
// bus queue of 2 s of frames. What load can still drop (a bridge or this test descheduled for
// longer) is counted: the sending bridge's bus queue (its subscriber's `dropped`), DDS write
// timeouts and lost samples (the bridges' exit lines), the viewer's own queue or pool steals
// (its `dropped`).
constexpr int kBridgeQueueDepth = 64;

std::vector<std::string> BridgeArgs(int dds_domain, const std::string& direction,
                                    const std::string& name) {
  std::vector<std::string> args = {"--ros-args", "-r", "__node:=" + name};
  for (const std::string& param :
       {direction + ":=[/camera/image]", "domain_id:=" + std::to_string(dds_domain),
        std::string("qos:=[\"/camera/.*=reliable,200,\"]"),
        "bus_queue_depth:=" + std::to_string(kBridgeQueueDepth),
        std::string("stats_period_s:=0")}) {
    args.insert(args.end(), {"-p", param});
  }
  return args;
}

// Drops the bus counted on /camera/image in `domain` so far: live subscribers' `dropped` (the
// sending bridge's queue in graph A, the viewer's in graph B).
uint64_t BusDrops(const std::string& domain) {
  uint64_t dropped = 0;
  for (const bus::TopicSnapshot& t : bus::ListTopics(domain)) {
    if (t.topic != "/camera/image") continue;
    for (const bus::SubscriberSnapshot& s : t.subscribers) {
      if (s.alive) dropped += s.dropped;
    }
  }
  return dropped;
}

// `dropped=` plus `errors=` of a bridge's exit line for `direction` ("/camera/image -> rt/" or
// "rt/camera/image -> /"); -1 (and a test failure) if the line is missing.
int64_t ExitDrops(const std::string& out, const std::string& direction) {
  const size_t line = out.find(direction);
  if (line == std::string::npos) {
    ADD_FAILURE() << "no '" << direction << "' line in:\n" << out;
    return -1;
  }
  auto field = [&](const std::string& key) -> int64_t {
    const size_t at = out.find(key, line);
    if (at == std::string::npos) return 0;
    return std::stoll(out.substr(at + key.size()));
  };
  return field(" dropped=") + field(" errors=");
}

// Publishes frames at ~30 Hz from `next` until the subscriber receives one (discovery done);
// returns the next free index. Fails after `timeout`.
uint32_t WaitForFlow(bus::Publisher& pub, bus::Subscriber& sub, uint32_t next,
                     std::chrono::seconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    PublishFrame(pub, next++);
    if (auto s = sub.Take(33ms)) {
      CheckFrame(*s);
      while (sub.Take(200ms)) {
      }
      return next;
    }
  }
  ADD_FAILURE() << "no frame crossed the bridges within " << timeout.count() << " s";
  return next;
}

// What a stream of frames gave: the indices received (in order of receipt) and the drops the
// bus counted meanwhile in both graphs.
struct StreamResult {
  std::vector<int64_t> received;
  uint64_t bus_drops = 0;     // sender_drops + viewer_drops
  uint64_t sender_drops = 0;  // the sending bridge's bus queue (graph A)
  uint64_t viewer_drops = 0;  // the viewer's queue or pool steals (graph B)
};

// Publishes `count` frames from `first` at 30 Hz; `a` and `b` are the sending and receiving graphs'
// bus domains.
StreamResult Stream(bus::Publisher& pub, bus::Subscriber& sub, uint32_t first, uint32_t count,
                    const std::string& a, const std::string& b) {
  const uint64_t sender_before = BusDrops(a), viewer_before = BusDrops(b);
  std::vector<int64_t> received;
  auto drain = [&](std::chrono::milliseconds wait) {
    while (auto s = sub.Take(wait)) {
      received.push_back(CheckFrame(*s));
      wait = 0ms;
    }
  };
  auto next = std::chrono::steady_clock::now();
  for (uint32_t i = 0; i < count; ++i) {
    PublishFrame(pub, first + i);
    next += 33ms;
    while (std::chrono::steady_clock::now() < next) {
      drain(std::chrono::duration_cast<std::chrono::milliseconds>(
          next - std::chrono::steady_clock::now()));
    }
  }
  // The bridges' queues hold seconds of frames: a bridge descheduled by load delivers its backlog
  // late, not never. So drain until every frame of the stream is received or counted as dropped
  // by the bus (DDS-side drops are known only from the bridges' exit lines), for at most 10 s,
  // then 0.3 s more, so that a frame arriving twice would be seen.
  auto accounted = [&] {
    const auto mine = std::count_if(received.begin(), received.end(),
                                    [&](int64_t i) { return i >= int64_t{first}; });
    return static_cast<uint64_t>(mine) + (BusDrops(a) - sender_before) +
               (BusDrops(b) - viewer_before) >=
           count;
  };
  const auto end = std::chrono::steady_clock::now() + 10s;
  while (std::chrono::steady_clock::now() < end && !accounted()) drain(100ms);
  drain(300ms);
  StreamResult r{std::move(received)};
  r.sender_drops = BusDrops(a) - sender_before;
  r.viewer_drops = BusDrops(b) - viewer_before;
  r.bus_drops = r.sender_drops + r.viewer_drops;
  return r;
}

// The stream's frames arrived in order, none twice, and every one that did not arrive was counted
// as dropped: by the bus (exactly, over the stream) or, when `dds_drops` >= 0, by the bridges
// (their lifetime DDS write timeouts, lost samples and errors). On a quiet machine nothing is
// dropped; under load a bridge or this test descheduled long enough drops by its queue policy,
// and that is counted, so this holds under any load. A frame neither received nor counted fails.
void ExpectDeliveredOrCounted(const StreamResult& r, uint32_t first, uint32_t count,
                              int64_t dds_drops = 0) {
  std::vector<int64_t> mine;
  for (int64_t i : r.received) {
    if (i >= first) mine.push_back(i);
  }
  for (size_t k = 1; k < mine.size(); ++k) {
    EXPECT_LT(mine[k - 1], mine[k]) << "out of order or twice";
  }
  ASSERT_FALSE(mine.empty()) << "nothing of the stream arrived";
  EXPECT_LT(mine.back(), int64_t{first} + count);
  const uint64_t missing = count - std::min<uint64_t>(count, mine.size());
  EXPECT_LE(r.bus_drops, missing) << "the bus counted more drops than frames went missing";
  EXPECT_LE(missing, r.bus_drops + static_cast<uint64_t>(std::max<int64_t>(dds_drops, 0)))
      << "received " << mine.size() << " of " << count << ", bus counted " << r.sender_drops
      << " dropped by the sending bridge's queue and " << r.viewer_drops << " by the viewer's, "
      << "bridges " << dds_drops << ": frames lost without being counted";
  if (missing > 0 &&
      missing <= r.bus_drops + static_cast<uint64_t>(std::max<int64_t>(dds_drops, 0))) {
    std::printf(
        "  %llu of %u frames dropped, all counted (sending bridge's bus queue %llu, viewer %llu, "
        "bridges' DDS side %lld)\n",
        static_cast<unsigned long long>(missing), count,
        static_cast<unsigned long long>(r.sender_drops),
        static_cast<unsigned long long>(r.viewer_drops), static_cast<long long>(dds_drops));
  }
}

TEST(DdsBridge, FramesCrossTwoGraphsIntactAndInOrder) {
  const int dds = DdsDomain(0);
  const std::string a = BusDomain("f", 'a'), b = BusDomain("f", 'b');
  CleanBusDomains clean{{a, b}};
  UseBusDomain(b);
  bus::Subscriber sub = MakeImageSubscriber();
  Process bridge_b("dds_bridge", BridgeArgs(dds, "from_dds", "bridge_b"));
  UseBusDomain(a);
  bus::Publisher pub = MakeImagePublisher();
  Process bridge_a("dds_bridge", BridgeArgs(dds, "to_dds", "bridge_a"));

  const uint32_t first = WaitForFlow(pub, sub, 0, 20s);
  const StreamResult stream = Stream(pub, sub, first, 90, a, b);

  // The sending bridge's exit line counts its bus queue's drops (in stream.bus_drops already) and
  // its DDS write timeouts in `dropped=`; its bus subscriber's lifetime count separates them.
  const uint64_t bridge_a_queue_drops = BusDrops(a);
  bridge_a.Signal(SIGINT);
  bridge_b.Signal(SIGINT);
  EXPECT_EQ(bridge_a.Wait(), 0) << bridge_a.Err();
  EXPECT_EQ(bridge_b.Wait(), 0) << bridge_b.Err();
  EXPECT_NE(bridge_a.Out().find("/camera/image -> rt/camera/image: forwarded="), std::string::npos)
      << bridge_a.Out();
  EXPECT_NE(bridge_b.Out().find("rt/camera/image -> /camera/image: forwarded="), std::string::npos)
      << bridge_b.Out();
  const int64_t sent = ExitDrops(bridge_a.Out(), "/camera/image -> rt/") -
                       static_cast<int64_t>(bridge_a_queue_drops);
  const int64_t got = ExitDrops(bridge_b.Out(), "rt/camera/image -> /");
  EXPECT_GE(sent, 0) << bridge_a.Out();
  ExpectDeliveredOrCounted(stream, first, 90, sent < 0 || got < 0 ? -1 : sent + got);
}

TEST(DdsBridge, PlainCycloneSubscriberDecodesOurImages) {
  const int dds = DdsDomain(1);
  const std::string a = BusDomain("p", 'a');
  CleanBusDomains clean{{a}};
  UseBusDomain(a);
  bus::Publisher pub = MakeImagePublisher();
  // Default image QoS (best effort, depth 2): what rviz2's default sensor-data subscription sees.
  Process bridge_a("dds_bridge", {"--ros-args", "-p", "to_dds:=[/camera/image]", "-p",
                                  "domain_id:=" + std::to_string(dds), "-p", "stats_period_s:=0"});

  // The same loopback configuration the bridge generates.
  const std::string config = dds_bridge::CycloneConfig(dds_bridge::BridgeOptions{});
  const dds_entity_t domain = dds_create_domain(static_cast<dds_domainid_t>(dds), config.c_str());
  ASSERT_GT(domain, 0) << dds_strretcode(domain);
  const dds_entity_t participant =
      dds_create_participant(static_cast<dds_domainid_t>(dds), nullptr, nullptr);
  ASSERT_GT(participant, 0);
  const dds_entity_t topic = dds_create_topic(participant, &sensor_msgs_msg_dds__Image__desc,
                                              "rt/camera/image", nullptr, nullptr);
  ASSERT_GT(topic, 0) << dds_strretcode(topic);
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 4);
  const dds_entity_t reader = dds_create_reader(participant, topic, qos, nullptr);
  dds_delete_qos(qos);
  ASSERT_GT(reader, 0) << dds_strretcode(reader);

  int decoded = 0;
  uint32_t index = 0;
  const auto deadline = std::chrono::steady_clock::now() + 25s;
  while (decoded < 5 && std::chrono::steady_clock::now() < deadline) {
    PublishFrame(pub, index++);
    std::this_thread::sleep_for(33ms);
    void* samples[1] = {nullptr};
    dds_sample_info_t info;
    while (dds_take(reader, samples, &info, 1, 1) > 0) {
      if (info.valid_data) {
        const auto* m = static_cast<const sensor_msgs_msg_dds__Image_*>(samples[0]);
        EXPECT_EQ(m->width, kWidth);
        EXPECT_EQ(m->height, kHeight);
        EXPECT_STREQ(m->encoding, "rgb8");
        EXPECT_EQ(m->is_bigendian, 0);
        EXPECT_EQ(m->step, kWidth * 3);
        EXPECT_STREQ(m->header.frame_id, "camera_optical");
        const int64_t stamp =
            int64_t{m->header.stamp.sec} * 1'000'000'000 + m->header.stamp.nanosec;
        const int64_t i = (stamp - kBaseStamp) / 1'000'000;
        EXPECT_GE(i, 0);
        EXPECT_LT(i, index);
        ASSERT_EQ(m->data._length, kWidth * kHeight * 3);
        bool intact = true;
        for (size_t j = 0; j < m->data._length && intact; ++j) {
          intact = m->data._buffer[j] == Pixel(static_cast<uint32_t>(i), j);
        }
        EXPECT_TRUE(intact) << "frame " << i;
        ++decoded;
      }
      dds_return_loan(reader, samples, 1);
      samples[0] = nullptr;
    }
  }
  EXPECT_GE(decoded, 5) << "decoded " << decoded << " images; bridge log:\n" << bridge_a.Err();
  dds_delete(domain);
}

// The other direction: a plain Cyclone writer (as a ROS 2 node would publish) reaches our bus.
TEST(DdsBridge, PlainCycloneWriterReachesTheBus) {
  const int dds = DdsDomain(3);
  const std::string b = BusDomain("w", 'b');
  CleanBusDomains clean{{b}};
  UseBusDomain(b);
  bus::Subscriber sub = [] {
    bus::SubscriberOptions o;
    o.queue_depth = 8;
    return bus::Subscriber("/robot/image", msgs::TopicTypeOf<msgs::Image>(), o);
  }();
  Process bridge_b("dds_bridge",
                   {"--ros-args", "-p", "from_dds:=[/ros/image:=/robot/image]", "-p",
                    "domain_id:=" + std::to_string(dds), "-p", "stats_period_s:=0", "-p",
                    "bus_slot_count:=12"});

  const std::string config = dds_bridge::CycloneConfig(dds_bridge::BridgeOptions{});
  const dds_entity_t domain = dds_create_domain(static_cast<dds_domainid_t>(dds), config.c_str());
  ASSERT_GT(domain, 0) << dds_strretcode(domain);
  const dds_entity_t participant =
      dds_create_participant(static_cast<dds_domainid_t>(dds), nullptr, nullptr);
  const dds_entity_t topic = dds_create_topic(participant, &sensor_msgs_msg_dds__Image__desc,
                                              "rt/ros/image", nullptr, nullptr);
  ASSERT_GT(topic, 0) << dds_strretcode(topic);
  const dds_entity_t writer = dds_create_writer(participant, topic, nullptr, nullptr);
  ASSERT_GT(writer, 0) << dds_strretcode(writer);

  constexpr uint32_t w = 64, h = 48;
  std::vector<uint8_t> pixels(w * h * 3);
  for (size_t j = 0; j < pixels.size(); ++j) pixels[j] = static_cast<uint8_t>(j * 13);
  sensor_msgs_msg_dds__Image_ m{};
  m.header.stamp.sec = 1'700'000'000;
  m.header.stamp.nanosec = 250'000'000;
  m.header.frame_id = const_cast<char*>("ros_camera");
  m.height = h;
  m.width = w;
  m.encoding = const_cast<char*>("rgb8");
  m.is_bigendian = 0;
  m.step = w * 3;
  m.data._length = m.data._maximum = static_cast<uint32_t>(pixels.size());
  m.data._buffer = pixels.data();
  m.data._release = false;

  std::optional<bus::Sample> got;
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  while (!got && std::chrono::steady_clock::now() < deadline) {
    ASSERT_EQ(dds_write(writer, &m), DDS_RETCODE_OK);
    got = sub.Take(50ms);
  }
  ASSERT_TRUE(got.has_value()) << "nothing arrived; bridge log:\n" << bridge_b.Err();
  const auto* image = got->As<msgs::Image>();
  EXPECT_EQ(image->width, w);
  EXPECT_EQ(image->height, h);
  EXPECT_EQ(image->encoding, msgs::Encoding::kRgb8);
  EXPECT_EQ(image->header.FrameId(), "ros_camera");
  EXPECT_EQ(image->header.stamp_ns, 1'700'000'000'250'000'000);
  ASSERT_EQ(got->data().size(), sizeof(msgs::Image) + pixels.size());
  EXPECT_EQ(std::memcmp(got->data().data() + sizeof(msgs::Image), pixels.data(), pixels.size()), 0);
  // The bridge's bus pool has the bus_slot_count param's slots.
  uint32_t slots = 0;
  for (const bus::TopicSnapshot& t : bus::ListTopics(b)) {
    if (t.topic != "/robot/image") continue;
    for (const bus::PublisherSnapshot& p : t.publishers) {
      if (p.alive) slots = p.slot_count;
    }
  }
  EXPECT_EQ(slots, 12u);
  got.reset();
  dds_delete(domain);
}

TEST(DdsBridge, BusSlotCountOutOfRangeIsABadParam) {
  UseBusDomain(BusDomain("s", 'b'));
  for (const char* value : {"1", "1025"}) {
    Process bridge("dds_bridge", {"--ros-args", "-p", "from_dds:=[/ros/image]", "-p",
                                  std::string("bus_slot_count:=") + value});
    EXPECT_EQ(bridge.Wait(), 2) << bridge.Err();
    EXPECT_NE(bridge.Err().find(std::string("bus_slot_count ") + value + " out of range (2..1024)"),
              std::string::npos)
        << bridge.Err();
  }
}

TEST(DdsBridge, KilledBridgeRestartsAndFlowResumes) {
  const int dds = DdsDomain(2);
  const std::string a = BusDomain("k", 'a'), b = BusDomain("k", 'b');
  CleanBusDomains clean{{a, b}};
  UseBusDomain(b);
  bus::Subscriber sub = MakeImageSubscriber();
  Process bridge_b("dds_bridge", BridgeArgs(dds, "from_dds", "bridge_b"));
  UseBusDomain(a);
  bus::Publisher pub = MakeImagePublisher();
  uint32_t next = 0;
  {
    Process bridge_a("dds_bridge", BridgeArgs(dds, "to_dds", "bridge_a"));
    next = WaitForFlow(pub, sub, next, 20s);
    ExpectDeliveredOrCounted(Stream(pub, sub, next, 30, a, b), next, 30);
    next += 30;
  }  // SIGKILL
  // Nothing crosses while the sender's bridge is down.
  for (int i = 0; i < 10; ++i) PublishFrame(pub, next++);
  while (sub.Take(300ms)) {
  }
  // Restarted under the same name: discovery again, and the flow resumes.
  Process bridge_a("dds_bridge", BridgeArgs(dds, "to_dds", "bridge_a"));
  next = WaitForFlow(pub, sub, next, 20s);
  ExpectDeliveredOrCounted(Stream(pub, sub, next, 30, a, b), next, 30);
  // And the receiving side survives a restart too.
  {
    bridge_b.Signal(SIGKILL);
    bridge_b.Wait();
  }
  UseBusDomain(b);
  Process bridge_b2("dds_bridge", BridgeArgs(dds, "from_dds", "bridge_b"));
  UseBusDomain(a);
  next += 30;
  next = WaitForFlow(pub, sub, next, 20s);
  ExpectDeliveredOrCounted(Stream(pub, sub, next, 30, a, b), next, 30);
}

}  // namespace
