// The Foxglove bridge: a WebSocket server (websocketpp + standalone asio, private) speaking the
// Foxglove protocol (protocol.h) over the Hub (hub.h), fed by bus subscriptions.
//
// Threads: the WebSocket io thread (handshakes, client messages, sending) and the bus thread.
// The bus thread rescans the bus every rescan_period (advertising topics that appeared,
// unadvertising those gone), subscribes to a bus topic only while some client subscribes to one
// of its channels (queue bus_queue_depth, drop-oldest, with the publishers' history for
// late-joined latched data such as camera info), and encodes each message once per channel —
// the converter's CDR, or a JPEG CompressedImage — then hands it to the Hub, which queues it for
// each subscribed client. The bus thread never waits for a client: a slow or stalled client only
// drops the oldest entries of its own queue, counted per client and per channel, and counted on
// the bridge's bus subscriber of that topic (bus::Subscriber::CountDownstreamDrops), so
// `probeless topic info` shows them as drops of the bridge's subscriber (under its node name),
// together with that subscriber's own bus-queue drops (the bridge itself falling behind), which
// BusTopicStats::dropped counts alone.
//
// Timestamps: messageData carries the bus receive time (CLOCK_REALTIME ns when the bridge took
// the message); time frames every time_period carry the same clock ("time" capability). With a
// clock_topic (the player's /clock, probeless_msgs/Header) the clock is instead the latest
// stamp_ns received on it — a replayed log's own time, as ROS's use_sim_time — and a time frame
// goes out when it advances (receive times are 0 until the first clock message).
//
// Network: 127.0.0.1 by default; address and port by option (port 0: a free port, see port()).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/foxglove/hub.h"

namespace probeless::foxglove {

struct ServerOptions {
  std::string address = "127.0.0.1";
  uint16_t port = 8765;
  // Protocol state: name, parameters, topic selection and JPEG topics, per-client queue limits.
  HubOptions hub;
  // Bytes handed to a client's socket and not yet written beyond which nothing more is sent to
  // it until it reads (its queue fills and drops instead); >= 64 KiB.
  size_t send_buffer_bytes = 4u << 20;
  // Bus queue per subscribed topic, 1..bus::kMaxQueueDepth.
  uint32_t bus_queue_depth = 4;
  // JPEG quality of the "<topic>/compressed" channels, 1..100.
  int jpeg_quality = 80;
  // Bus rescan and time frame periods, seconds (> 0).
  double rescan_period_s = 0.25;
  double time_period_s = 0.1;
  // A probeless_msgs/Header topic whose stamp_ns is the clock (e.g. "/clock"); empty: wall clock.
  std::string clock_topic;
  // Bus domain (default: this process's).
  std::string domain;
  // Shown by bus introspection for the bridge's subscribers.
  std::string node_name = "/foxglove_bridge";
  // Notices and warnings ("warning: ..."), one line each, from the bridge's threads (one call at
  // a time); may be empty.
  std::function<void(std::string_view line)> log;
};

// The bus side of one topic.
struct BusTopicStats {
  std::string topic;
  uint64_t received = 0;  // messages taken from the bus
  // Lost in the bridge's bus queue, all its subscribers' lives (Subscriber::dropped without the
  // client-queue drops counted on it, which ChannelStats::dropped has).
  uint64_t dropped = 0;
  uint64_t errors = 0;  // messages that failed to encode
  bool subscribed = false;
};

struct ServerStats {
  std::vector<BusTopicStats> topics;
  std::vector<ChannelStats> channels;
  std::vector<ClientStats> clients;
};

class Server {
 public:
  // Checks the options and binds the address; throws FoxgloveError (one line) for bad options or
  // an address/port that cannot be used.
  explicit Server(ServerOptions options);
  ~Server();  // Stop()
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // The bound port.
  uint16_t port() const;
  // Starts the io and bus threads (first bus scan done before it returns).
  void Start();
  // Closes every connection, stops and joins both threads. Idempotent.
  void Stop();
  ServerStats Stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace probeless::foxglove
