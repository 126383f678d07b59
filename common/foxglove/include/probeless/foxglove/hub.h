// The protocol state of a Foxglove bridge, apart from any socket: the channel table, every
// connected client with its subscriptions and its ClientQueue, and the fan-out of encoded
// messages to the subscribed clients. The server (server.h) feeds it from its WebSocket thread
// (Connect, HandleText, HandleBinary, Pop, Disconnect) and its bus thread (UpdateTopics,
// SubscribedChannels, Publish, BroadcastTime); tests drive it directly.
//
// Client errors never close a connection: a malformed or refused message is answered with an
// error status (level 2) whose message is the ProtocolError's line, and the client stays
// connected with its subscriptions. Only a client that does not read at all (its control lane
// overflows) is reported by Overflowed() for the server to close.
//
// Thread safety: every member may be called from any thread (one mutex; the wake callback is
// called outside it).
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/foxglove/channels.h"
#include "probeless/foxglove/client_queue.h"
#include "probeless/foxglove/protocol.h"

namespace probeless::foxglove {

struct HubOptions {
  std::string server_name = "probeless foxglove_bridge";
  std::map<std::string, std::string> metadata;
  std::string session_id;
  // Served read-only through getParameters ("parameters" capability).
  std::vector<Parameter> parameters;
  ChannelTableOptions channels;
  QueueLimits limits;
  // At most one warning status per client this often about its queue's drops (ns; 0: never).
  int64_t drop_status_period_ns = 5'000'000'000;
  // Called (outside the hub's lock) for each client that has something new to send.
  std::function<void(uint64_t client)> wake;
};

struct ClientStats {
  uint64_t id = 0;
  std::string remote;
  size_t subscriptions = 0;
  uint64_t sent = 0;     // messageData frames popped for sending
  uint64_t dropped = 0;  // messageData frames dropped by its queue
  uint64_t errors = 0;   // client messages answered with an error status
  size_t queued = 0;
};

struct ChannelStats {
  uint32_t id = 0;
  std::string topic;
  uint32_t subscribers = 0;
  uint64_t messages = 0;  // encoded and handed to the subscribed clients' queues
  uint64_t bytes = 0;     // their payload bytes (once per message, not per client)
  uint64_t dropped = 0;   // queue drops of this channel, summed over clients (departed included)
};

class Hub {
 public:
  // Throws FoxgloveError for bad channel options or queue limits.
  explicit Hub(HubOptions options);
  ~Hub();
  Hub(const Hub&) = delete;
  Hub& operator=(const Hub&) = delete;

  // The capabilities announced in serverInfo: "time", "parameters".
  static std::vector<std::string> Capabilities();

  // --- Clients ---
  // Registers a client and queues its serverInfo and the advertise of every current channel.
  // Returns its id (1, 2, ...).
  uint64_t Connect(std::string remote);
  // Forgets a client, its queue and subscriptions (unknown ids are ignored).
  void Disconnect(uint64_t client);
  // Handles one text message of a client: subscribe, unsubscribe, getParameters; anything else
  // gets an error status (see ProtocolError).
  void HandleText(uint64_t client, std::string_view text);
  // Binary client messages are all refused with an error status.
  void HandleBinary(uint64_t client, std::span<const std::byte> data);
  // The next frame to send to `client`; nullopt if none (or unknown client).
  std::optional<OutgoingFrame> Pop(uint64_t client);
  // True once the client left its control lane unread beyond QueueLimits::max_control.
  bool Overflowed(uint64_t client) const;

  // --- Bus side ---
  // Updates the channel table from a full listing of bus topics, advertises added channels and
  // unadvertises removed ones to every client (dropping their subscriptions to them). Returns
  // the changes (warnings included) for the caller to log.
  ChannelChanges UpdateTopics(std::span<const BusTopic> topics);
  // Bumped by every change of the set of subscribed channels.
  uint64_t subscription_generation() const;
  // The channels with at least one subscriber (copies), by id.
  std::vector<ChannelEntry> SubscribedChannels() const;
  // Queues `message` for every client subscribed to its channel (each queue drops its oldest
  // when full); counts it for the channel. Returns the entries the clients' queues dropped for
  // it (summed over clients), for the caller to count against the bus subscriber the message
  // came from (bus::Subscriber::CountDownstreamDrops).
  size_t Publish(std::shared_ptr<const EncodedMessage> message);
  // Queues a time frame for every client.
  void BroadcastTime(uint64_t timestamp_ns);

  std::vector<ClientStats> Clients() const;
  std::vector<ChannelStats> Channels() const;

 private:
  struct Client;
  void Status(Client& c, StatusLevel level, const std::string& message);
  void Subscribe(Client& c, const SubscribeRequest& r);
  void Unsubscribe(Client& c, const UnsubscribeRequest& r);
  void Wake(const std::vector<uint64_t>& clients) const;

  HubOptions options_;
  mutable std::mutex mutex_;
  ChannelTable table_;
  std::map<uint64_t, std::unique_ptr<Client>> clients_;
  uint64_t next_client_ = 1;
  uint64_t generation_ = 0;
  std::map<uint32_t, ChannelStats> channel_stats_;
};

}  // namespace probeless::foxglove
