#include "probeless/foxglove/server.h"

#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <stdexcept>
#include <thread>

#include "probeless/bus/bus.h"
#include "probeless/foxglove/jpeg.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/header.h"
#include "ws_transport.h"

namespace probeless::foxglove {
namespace {

using Clock = std::chrono::steady_clock;
// Longest wait of the bus thread, so subscription changes apply within it.
constexpr auto kMaxWait = std::chrono::milliseconds(20);

uint64_t RealtimeNs() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<uint64_t>(ts.tv_sec) * 1'000'000'000ull + static_cast<uint64_t>(ts.tv_nsec);
}

std::chrono::nanoseconds Seconds(double s) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(s));
}

}  // namespace

struct Server::Impl {
  ServerOptions options;
  std::unique_ptr<Hub> hub;
  std::unique_ptr<internal::WsTransport> transport;
  std::atomic<internal::WsTransport*> wake_target{nullptr};
  std::mutex log_mutex;

  std::thread bus_thread;
  std::atomic<bool> stopping{false};
  std::mutex stop_mutex;
  std::condition_variable stop_cv;
  bool started = false;
  bool stopped = false;

  // Bus thread state.
  struct Topic {
    std::string name;
    bus::TopicType type;
    std::unique_ptr<bus::Subscriber> subscriber;
    std::vector<ChannelEntry> channels;
    // Client-queue drops of its messages counted into subscriber's dropped() (so `probeless
    // topic info` shows them); subtracted again for BusTopicStats::dropped (bus queue only).
    uint64_t downstream_dropped = 0;
  };
  std::map<std::string, Topic> topics;  // subscribed bus topics
  std::unique_ptr<bus::WaitSet> wait_set;
  std::vector<Topic*> wait_order;  // WaitSet index -> topic
  log::CdrWriter writer;
  std::set<std::string> warned;
  // Bus-queue drops of earlier subscribers per topic (client-queue drops excluded).
  std::map<std::string, uint64_t> dropped_before;

  // The clock_topic subscriber and its latest stamp (bus thread).
  std::unique_ptr<bus::Subscriber> clock;
  uint64_t clock_ns = 0;
  uint64_t clock_sent_ns = 0;

  // The time of messages and time frames: the wall clock, or the clock topic's.
  uint64_t NowNs() {
    if (!clock) return RealtimeNs();
    while (std::optional<bus::Sample> s = clock->TryTake()) {
      try {
        const int64_t stamp = msgs::ReadMessage<msgs::Header>(s->data())->stamp_ns;
        if (stamp >= 0) clock_ns = static_cast<uint64_t>(stamp);
      } catch (const msgs::MessageError&) {
      }
    }
    return clock_ns;
  }

  mutable std::mutex stats_mutex;
  std::map<std::string, BusTopicStats> topic_stats;

  void Log(const std::string& line) {
    if (!options.log) return;
    std::lock_guard lock(log_mutex);
    options.log(line);
  }

  void Scan() {
    std::vector<BusTopic> list;
    for (const bus::TopicSnapshot& s : bus::ListTopics(options.domain)) {
      list.push_back({s.topic, s.type.name, s.type.layout_hash});
    }
    const ChannelChanges changes = hub->UpdateTopics(list);
    for (const std::string& n : changes.notices) Log(n);
    for (const std::string& w : changes.warnings) Log("warning: " + w);
    for (const Channel& c : changes.added) {
      Log("advertising " + c.topic + " (" + c.schema_name + ", " + c.encoding + ") as channel " +
          std::to_string(c.id));
    }
    for (uint32_t id : changes.removed) Log("channel " + std::to_string(id) + " is gone");
  }

  void Resubscribe() {
    std::map<std::string, std::vector<ChannelEntry>> wanted;
    for (ChannelEntry& e : hub->SubscribedChannels()) wanted[e.bus_topic].push_back(e);
    bool changed = false;
    for (auto it = topics.begin(); it != topics.end();) {
      const auto w = wanted.find(it->first);
      const bool keep = w != wanted.end() && w->second.front().type == it->second.type.name &&
                        w->second.front().layout_hash == it->second.type.layout_hash;
      if (keep) {
        it->second.channels = w->second;
        ++it;
        continue;
      }
      dropped_before[it->first] += BusQueueDropped(it->second);
      Log("unsubscribed from " + it->first);
      it = topics.erase(it);
      changed = true;
    }
    for (auto& [name, channels] : wanted) {
      if (topics.contains(name)) continue;
      Topic t;
      t.name = name;
      t.type = {channels.front().type, channels.front().layout_hash};
      t.channels = channels;
      bus::SubscriberOptions so;
      so.queue_depth = options.bus_queue_depth;
      so.receive_history = true;
      so.node_name = options.node_name;
      try {
        t.subscriber = std::make_unique<bus::Subscriber>(name, t.type, so);
      } catch (const bus::BusError& e) {
        Log(std::string("warning: cannot subscribe to ") + name + ": " + e.what());
        continue;
      }
      Log("subscribed to " + name);
      topics.emplace(name, std::move(t));
      changed = true;
    }
    if (!changed) return;
    wait_set = std::make_unique<bus::WaitSet>();
    wait_order.clear();
    for (auto& [name, t] : topics) {
      wait_set->Add(*t.subscriber);
      wait_order.push_back(&t);
    }
    std::lock_guard lock(stats_mutex);
    for (auto& [name, s] : topic_stats) s.subscribed = topics.contains(name);
    for (auto& [name, t] : topics) {
      BusTopicStats& s = topic_stats[name];
      s.topic = name;
      s.subscribed = true;
    }
  }

  void Handle(Topic& t, const bus::Sample& sample) {
    const uint64_t receive_ns = NowNs();
    uint64_t errors = 0;
    for (const ChannelEntry& e : t.channels) {
      auto message = std::make_shared<EncodedMessage>();
      message->channel_id = e.channel.id;
      message->receive_ns = receive_ns;
      try {
        writer.Reset();
        if (e.kind == ChannelKind::kJpeg) {
          EncodeCompressedImageCdr(sample.data(), options.jpeg_quality, writer);
        } else {
          e.converter->Encode(sample.data(), writer);
        }
        message->payload = writer.Take();
      } catch (const std::exception& error) {
        ++errors;
        if (warned.insert(e.channel.topic).second) {
          Log("warning: " + e.channel.topic + ": message " +
              std::to_string(sample.info().sequence) + " not sent: " + error.what() +
              " (further failures are only counted)");
        }
        continue;
      }
      // Drops in the clients' queues are drops of the bridge's subscriber on this topic: counted
      // on it at once (before the next channel's encoding), in the bus thread that owns it (the
      // queues drop only inside Hub::Publish).
      if (const size_t downstream = hub->Publish(std::move(message)); downstream > 0) {
        t.subscriber->CountDownstreamDrops(downstream);
        t.downstream_dropped += downstream;
      }
    }
    std::lock_guard lock(stats_mutex);
    BusTopicStats& s = topic_stats[t.name];
    ++s.received;
    s.errors += errors;
  }

  static uint64_t BusQueueDropped(const Topic& t) {
    return t.subscriber->dropped() - t.downstream_dropped;
  }

  void UpdateDropped() {
    std::lock_guard lock(stats_mutex);
    for (auto& [name, s] : topic_stats) {
      const auto t = topics.find(name);
      s.dropped = dropped_before[name] + (t != topics.end() ? BusQueueDropped(t->second) : 0);
    }
  }

  void BusLoop() {
    uint64_t generation = ~uint64_t{0};
    auto next_scan = Clock::now() + Seconds(options.rescan_period_s);
    auto next_time = Clock::now();
    while (!stopping) {
      auto now = Clock::now();
      if (now >= next_scan) {
        Scan();
        next_scan = now + Seconds(options.rescan_period_s);
      }
      if (const uint64_t g = hub->subscription_generation(); g != generation) {
        generation = g;
        Resubscribe();
      }
      if (now >= next_time) {
        const uint64_t t = NowNs();
        if (!clock || t != clock_sent_ns) hub->BroadcastTime(t);
        clock_sent_ns = t;
        next_time = now + Seconds(options.time_period_s);
      }
      const auto wait = std::clamp<std::chrono::nanoseconds>(
          std::min(next_scan, next_time) - Clock::now(), std::chrono::nanoseconds(0), kMaxWait);
      if (!topics.empty()) {
        for (size_t index : wait_set->Wait(wait)) {
          Topic& t = *wait_order[index];
          // At most one queue's worth per topic per pass, so every topic gets its turn.
          for (uint32_t n = 0; n < options.bus_queue_depth; ++n) {
            std::optional<bus::Sample> sample = t.subscriber->TryTake();
            if (!sample) break;
            Handle(t, *sample);
          }
        }
      } else {
        std::unique_lock lock(stop_mutex);
        stop_cv.wait_for(lock, wait, [&] { return stopping.load(); });
      }
      UpdateDropped();
    }
    topics.clear();
    wait_set.reset();
  }
};

Server::Server(ServerOptions options) : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  if (options.send_buffer_bytes < (64u << 10)) {
    throw FoxgloveError("send buffer " + std::to_string(options.send_buffer_bytes) +
                        " bytes is below 64 KiB");
  }
  if (options.bus_queue_depth < 1 || options.bus_queue_depth > bus::kMaxQueueDepth) {
    throw FoxgloveError("bus queue depth " + std::to_string(options.bus_queue_depth) +
                        " out of range (1.." + std::to_string(bus::kMaxQueueDepth) + ")");
  }
  if (options.jpeg_quality < 1 || options.jpeg_quality > 100) {
    throw FoxgloveError("JPEG quality " + std::to_string(options.jpeg_quality) +
                        " out of range (1..100)");
  }
  if (!(options.rescan_period_s > 0) || !(options.time_period_s > 0)) {
    throw FoxgloveError("rescan and time periods must be > 0 s");
  }
  if (options.domain.empty()) options.domain = bus::CurrentDomain();
  if (!options.clock_topic.empty()) {
    try {
      bus::SubscriberOptions so;
      so.queue_depth = 4;
      so.node_name = options.node_name;
      s.clock = std::make_unique<bus::Subscriber>(options.clock_topic,
                                                  msgs::TopicTypeOf<msgs::Header>(), so);
    } catch (const bus::BusError& e) {
      throw FoxgloveError(std::string("clock topic: ") + e.what());
    }
  }
  s.options = std::move(options);
  HubOptions hub_options = s.options.hub;
  hub_options.wake = [&s](uint64_t client) {
    if (internal::WsTransport* t = s.wake_target.load()) t->Wake(client);
  };
  s.hub = std::make_unique<Hub>(std::move(hub_options));

  internal::TransportOptions to;
  to.address = s.options.address;
  to.port = s.options.port;
  to.send_buffer_bytes = s.options.send_buffer_bytes;
  internal::TransportCallbacks cb;
  cb.choose_subprotocol = [](const std::vector<std::string>& offered) {
    return std::string(ChooseSubprotocol(offered));
  };
  cb.open = [&s](const std::string& remote) { return s.hub->Connect(remote); };
  cb.close = [&s](uint64_t id) { s.hub->Disconnect(id); };
  cb.message = [&s](uint64_t id, const std::string& payload, bool binary) {
    if (binary) {
      s.hub->HandleBinary(id, std::as_bytes(std::span(payload.data(), payload.size())));
    } else {
      s.hub->HandleText(id, payload);
    }
  };
  cb.pop = [&s](uint64_t id) { return s.hub->Pop(id); };
  cb.overflowed = [&s](uint64_t id) { return s.hub->Overflowed(id); };
  cb.log = [&s](const std::string& line) { s.Log(line); };
  try {
    s.transport = std::make_unique<internal::WsTransport>(to, std::move(cb));
  } catch (const std::runtime_error& e) {
    throw FoxgloveError(e.what());
  }
}

Server::~Server() { Stop(); }

uint16_t Server::port() const { return impl_->transport->port(); }

void Server::Start() {
  Impl& s = *impl_;
  if (s.started) return;
  s.started = true;
  s.Scan();
  s.wake_target = s.transport.get();
  s.transport->Start();
  s.bus_thread = std::thread([&s] { s.BusLoop(); });
}

void Server::Stop() {
  Impl& s = *impl_;
  if (!s.started || s.stopped) return;
  s.stopped = true;
  {
    std::lock_guard lock(s.stop_mutex);
    s.stopping = true;
  }
  s.stop_cv.notify_all();
  s.bus_thread.join();
  s.transport->Stop();
  s.wake_target = nullptr;
}

ServerStats Server::Stats() const {
  const Impl& s = *impl_;
  ServerStats out;
  {
    std::lock_guard lock(s.stats_mutex);
    for (const auto& [name, t] : s.topic_stats) out.topics.push_back(t);
  }
  out.channels = s.hub->Channels();
  out.clients = s.hub->Clients();
  return out;
}

}  // namespace probeless::foxglove
