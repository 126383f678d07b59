// The bounded queue of what is waiting to be sent to one client.
//
// Two lanes: control (JSON text: serverInfo, advertise, status, parameterValues, and time
// frames), sent first and never dropped but bounded — a client that leaves more than
// max_control of them unread is not reading at all and is to be disconnected (Overflowed()); and
// data (messageData frames, in arrival order), bounded per subscription by a message count (a
// fast image stream never pushes a slow light stream out) and for the whole client by a byte
// budget, dropping the oldest entries: of the same subscription when its count is reached, of
// any subscription when the bytes are. Drops are counted per channel. A data payload is shared
// by every client that gets it (encoded once, referenced here).
//
// Thread safety: every member may be called from any thread (one mutex).
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace probeless::foxglove {

// One encoded message of a channel, shared by the queues of every subscribed client.
struct EncodedMessage {
  uint32_t channel_id = 0;
  uint64_t receive_ns = 0;  // the messageData timestamp
  std::vector<std::byte> payload;
};

// One item to send: a text frame, a binary control frame (time), or a messageData frame (its
// 13-byte header from subscription_id and message->receive_ns, then message->payload).
struct OutgoingFrame {
  enum class Kind { kText, kBinary, kMessageData };
  Kind kind = Kind::kText;
  std::string bytes;  // kText, kBinary
  uint32_t subscription_id = 0;
  std::shared_ptr<const EncodedMessage> message;  // kMessageData
};

struct QueueLimits {
  size_t max_messages = 10;        // data entries, >= 1
  size_t max_bytes = 64ull << 20;  // data payload bytes (at least one message always fits)
  size_t max_control = 1024;       // control entries before the client counts as stalled
};

class ClientQueue {
 public:
  explicit ClientQueue(QueueLimits limits);

  // Appends a control frame (text or binary). Beyond max_control queued, nothing is added and
  // Overflowed() turns true.
  void PushControl(std::string bytes, bool binary);
  // Queues a time frame, replacing one still queued (only the latest server time matters), so a
  // client that stops reading for a while is not disconnected for unread clock ticks.
  void PushTime(std::string frame);
  // Appends a messageData entry; drops the oldest entry of the same subscription while it has
  // max_messages queued, then the oldest entries while the bytes would exceed max_bytes (the new
  // one is always kept). Returns how many were dropped.
  size_t PushData(uint32_t subscription_id, std::shared_ptr<const EncodedMessage> message);
  // Removes the queued data of one subscription (an unsubscribe: not counted as drops).
  void RemoveSubscription(uint32_t subscription_id);
  // The next frame to send: control first, then data in order; nullopt when empty.
  std::optional<OutgoingFrame> Pop();

  bool Overflowed() const;
  // Data entries dropped so far, in total and per channel id.
  uint64_t dropped() const;
  std::map<uint32_t, uint64_t> dropped_by_channel() const;
  // Data entries sent (popped) so far. queued_messages: data entries queued, all subscriptions.
  uint64_t sent() const;
  size_t queued_messages() const;
  size_t queued_bytes() const;

 private:
  struct Data {
    uint32_t subscription_id;
    std::shared_ptr<const EncodedMessage> message;
  };
  const QueueLimits limits_;
  mutable std::mutex mutex_;
  std::deque<OutgoingFrame> control_;
  bool time_queued_ = false;  // control_ holds a time frame (the only binary control frames)
  std::deque<Data> data_;
  std::map<uint32_t, size_t> queued_by_subscription_;
  size_t data_bytes_ = 0;
  bool overflowed_ = false;
  uint64_t dropped_ = 0;
  uint64_t sent_ = 0;
  std::map<uint32_t, uint64_t> dropped_by_channel_;
};

}  // namespace probeless::foxglove
