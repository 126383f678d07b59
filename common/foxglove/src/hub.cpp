#include "probeless/foxglove/hub.h"

#include <algorithm>
#include <utility>
#include <variant>

namespace probeless::foxglove {

struct Hub::Client {
  explicit Client(QueueLimits limits) : queue(limits) {}
  uint64_t id = 0;
  std::string remote;
  ClientQueue queue;
  std::map<uint32_t, uint32_t> subscriptions;  // subscription id -> channel id
  std::map<uint32_t, uint32_t> by_channel;     // channel id -> subscription id
  uint64_t errors = 0;
  uint64_t dropped_reported = 0;
  int64_t last_drop_status_ns = 0;
};

Hub::Hub(HubOptions options) : options_(std::move(options)), table_(options_.channels) {
  // The limits are checked here, once, by a queue made for that (it throws on bad ones), not at
  // the first Connect.
  [[maybe_unused]] const ClientQueue check(options_.limits);
}

Hub::~Hub() = default;

std::vector<std::string> Hub::Capabilities() { return {"time", "parameters"}; }

uint64_t Hub::Connect(std::string remote) {
  uint64_t id;
  {
    std::lock_guard lock(mutex_);
    id = next_client_++;
    auto c = std::make_unique<Client>(options_.limits);
    c->id = id;
    c->remote = std::move(remote);
    ServerInfo info{options_.server_name, Capabilities(), options_.metadata, options_.session_id};
    c->queue.PushControl(ServerInfoJson(info), false);
    const std::vector<Channel> channels = table_.Channels();
    c->queue.PushControl(AdvertiseJson(channels), false);
    clients_.emplace(id, std::move(c));
  }
  Wake({id});
  return id;
}

void Hub::Disconnect(uint64_t client) {
  std::lock_guard lock(mutex_);
  const auto it = clients_.find(client);
  if (it == clients_.end()) return;
  if (!it->second->subscriptions.empty()) ++generation_;
  clients_.erase(it);
}

void Hub::Status(Client& c, StatusLevel level, const std::string& message) {
  if (level == StatusLevel::kError) ++c.errors;
  c.queue.PushControl(StatusJson(level, message), false);
}

void Hub::Subscribe(Client& c, const SubscribeRequest& r) {
  for (const Subscription& s : r.subscriptions) {
    if (c.subscriptions.contains(s.id)) {
      Status(c, StatusLevel::kError,
             "subscribe: subscription id " + std::to_string(s.id) + " is already in use");
      continue;
    }
    if (table_.Find(s.channel_id) == nullptr) {
      Status(c, StatusLevel::kError,
             "subscribe: channel " + std::to_string(s.channel_id) + " is not advertised");
      continue;
    }
    if (const auto it = c.by_channel.find(s.channel_id); it != c.by_channel.end()) {
      Status(c, StatusLevel::kError,
             "subscribe: channel " + std::to_string(s.channel_id) +
                 " is already subscribed (subscription " + std::to_string(it->second) + ")");
      continue;
    }
    c.subscriptions.emplace(s.id, s.channel_id);
    c.by_channel.emplace(s.channel_id, s.id);
    ++generation_;
  }
}

void Hub::Unsubscribe(Client& c, const UnsubscribeRequest& r) {
  for (uint32_t id : r.subscription_ids) {
    const auto it = c.subscriptions.find(id);
    if (it == c.subscriptions.end()) {
      Status(c, StatusLevel::kError,
             "unsubscribe: subscription " + std::to_string(id) + " does not exist");
      continue;
    }
    c.by_channel.erase(it->second);
    c.subscriptions.erase(it);
    c.queue.RemoveSubscription(id);
    ++generation_;
  }
}

void Hub::HandleText(uint64_t client, std::string_view text) {
  {
    std::lock_guard lock(mutex_);
    const auto it = clients_.find(client);
    if (it == clients_.end()) return;
    Client& c = *it->second;
    try {
      const ClientRequest request = ParseClientText(text);
      if (const auto* s = std::get_if<SubscribeRequest>(&request)) {
        Subscribe(c, *s);
      } else if (const auto* u = std::get_if<UnsubscribeRequest>(&request)) {
        Unsubscribe(c, *u);
      } else if (const auto* g = std::get_if<GetParametersRequest>(&request)) {
        c.queue.PushControl(ParameterValuesJson(options_.parameters, g->names, g->id), false);
      }
    } catch (const ProtocolError& e) {
      Status(c, StatusLevel::kError, e.what());
    }
  }
  Wake({client});
}

void Hub::HandleBinary(uint64_t client, std::span<const std::byte> data) {
  {
    std::lock_guard lock(mutex_);
    const auto it = clients_.find(client);
    if (it == clients_.end()) return;
    try {
      RejectClientBinary(data);
    } catch (const ProtocolError& e) {
      Status(*it->second, StatusLevel::kError, e.what());
    }
  }
  Wake({client});
}

std::optional<OutgoingFrame> Hub::Pop(uint64_t client) {
  std::lock_guard lock(mutex_);
  const auto it = clients_.find(client);
  if (it == clients_.end()) return std::nullopt;
  return it->second->queue.Pop();
}

bool Hub::Overflowed(uint64_t client) const {
  std::lock_guard lock(mutex_);
  const auto it = clients_.find(client);
  return it != clients_.end() && it->second->queue.Overflowed();
}

ChannelChanges Hub::UpdateTopics(std::span<const BusTopic> topics) {
  std::vector<uint64_t> touched;
  ChannelChanges changes;
  {
    std::lock_guard lock(mutex_);
    changes = table_.Update(topics);
    if (changes.added.empty() && changes.removed.empty()) return changes;
    for (const Channel& ch : changes.added) {
      ChannelStats& s = channel_stats_[ch.id];
      s.id = ch.id;
      s.topic = ch.topic;
    }
    for (auto& [id, c] : clients_) {
      for (uint32_t channel : changes.removed) {
        const auto sub = c->by_channel.find(channel);
        if (sub == c->by_channel.end()) continue;
        c->queue.RemoveSubscription(sub->second);
        c->subscriptions.erase(sub->second);
        c->by_channel.erase(sub);
        ++generation_;
      }
      if (!changes.removed.empty()) c->queue.PushControl(UnadvertiseJson(changes.removed), false);
      if (!changes.added.empty()) c->queue.PushControl(AdvertiseJson(changes.added), false);
      touched.push_back(id);
    }
  }
  Wake(touched);
  return changes;
}

uint64_t Hub::subscription_generation() const {
  std::lock_guard lock(mutex_);
  return generation_;
}

std::vector<ChannelEntry> Hub::SubscribedChannels() const {
  std::lock_guard lock(mutex_);
  std::map<uint32_t, ChannelEntry> out;
  for (const auto& [id, c] : clients_) {
    for (const auto& [channel, sub] : c->by_channel) {
      if (const ChannelEntry* e = table_.Find(channel)) out.emplace(channel, *e);
    }
  }
  std::vector<ChannelEntry> list;
  for (auto& [id, e] : out) list.push_back(std::move(e));
  return list;
}

size_t Hub::Publish(std::shared_ptr<const EncodedMessage> message) {
  std::vector<uint64_t> touched;
  size_t dropped_total = 0;
  {
    std::lock_guard lock(mutex_);
    const auto stats = channel_stats_.find(message->channel_id);
    if (stats == channel_stats_.end()) return 0;
    ++stats->second.messages;
    stats->second.bytes += message->payload.size();
    for (auto& [id, c] : clients_) {
      const auto sub = c->by_channel.find(message->channel_id);
      if (sub == c->by_channel.end()) continue;
      const size_t dropped = c->queue.PushData(sub->second, message);
      stats->second.dropped += dropped;
      dropped_total += dropped;
      const int64_t now = static_cast<int64_t>(message->receive_ns);
      const uint64_t total = c->queue.dropped();
      if (options_.drop_status_period_ns > 0 && total > c->dropped_reported &&
          now - c->last_drop_status_ns >= options_.drop_status_period_ns) {
        Status(*c, StatusLevel::kWarning,
               "dropped " + std::to_string(total - c->dropped_reported) +
                   " messages: this connection is slower than the subscribed streams (" +
                   std::to_string(total) + " dropped so far)");
        c->dropped_reported = total;
        c->last_drop_status_ns = now;
      }
      touched.push_back(id);
    }
  }
  Wake(touched);
  return dropped_total;
}

void Hub::BroadcastTime(uint64_t timestamp_ns) {
  std::vector<uint64_t> touched;
  {
    std::lock_guard lock(mutex_);
    const std::string frame = TimeFrame(timestamp_ns);
    for (auto& [id, c] : clients_) {
      c->queue.PushTime(frame);
      touched.push_back(id);
    }
  }
  Wake(touched);
}

std::vector<ClientStats> Hub::Clients() const {
  std::lock_guard lock(mutex_);
  std::vector<ClientStats> out;
  for (const auto& [id, c] : clients_) {
    out.push_back({id, c->remote, c->subscriptions.size(), c->queue.sent(), c->queue.dropped(),
                   c->errors, c->queue.queued_messages()});
  }
  return out;
}

std::vector<ChannelStats> Hub::Channels() const {
  std::lock_guard lock(mutex_);
  std::map<uint32_t, uint32_t> subscribers;
  for (const auto& [id, c] : clients_) {
    for (const auto& [channel, sub] : c->by_channel) ++subscribers[channel];
  }
  std::vector<ChannelStats> out;
  for (const auto& [id, s] : channel_stats_) {
    if (table_.Find(id) == nullptr && s.messages == 0) continue;
    ChannelStats copy = s;
    copy.subscribers = subscribers[id];
    out.push_back(copy);
  }
  return out;
}

void Hub::Wake(const std::vector<uint64_t>& clients) const {
  if (!options_.wake) return;
  for (uint64_t id : clients) options_.wake(id);
}

}  // namespace probeless::foxglove
