#include "probeless/foxglove/client_queue.h"

#include <algorithm>

#include "probeless/foxglove/protocol.h"

namespace probeless::foxglove {

ClientQueue::ClientQueue(QueueLimits limits) : limits_(limits) {
  if (limits_.max_messages == 0) throw FoxgloveError("client queue depth must be >= 1");
  if (limits_.max_control == 0) throw FoxgloveError("client control queue must be >= 1");
}

void ClientQueue::PushControl(std::string bytes, bool binary) {
  std::lock_guard lock(mutex_);
  if (control_.size() >= limits_.max_control) {
    overflowed_ = true;
    return;
  }
  OutgoingFrame f;
  f.kind = binary ? OutgoingFrame::Kind::kBinary : OutgoingFrame::Kind::kText;
  f.bytes = std::move(bytes);
  control_.push_back(std::move(f));
}

void ClientQueue::PushTime(std::string frame) {
  {
    std::lock_guard lock(mutex_);
    if (time_queued_) {
      for (OutgoingFrame& f : control_) {
        if (f.kind == OutgoingFrame::Kind::kBinary) {
          f.bytes = std::move(frame);
          return;
        }
      }
    }
    time_queued_ = true;
  }
  PushControl(std::move(frame), true);
}

size_t ClientQueue::PushData(uint32_t subscription_id,
                             std::shared_ptr<const EncodedMessage> message) {
  std::lock_guard lock(mutex_);
  const size_t bytes = message->payload.size();
  size_t dropped = 0;
  auto drop = [&](std::deque<Data>::iterator it) {
    data_bytes_ -= it->message->payload.size();
    ++dropped_by_channel_[it->message->channel_id];
    --queued_by_subscription_[it->subscription_id];
    ++dropped;
    return data_.erase(it);
  };
  if (queued_by_subscription_[subscription_id] >= limits_.max_messages) {
    for (auto it = data_.begin(); it != data_.end(); ++it) {
      if (it->subscription_id == subscription_id) {
        drop(it);
        break;
      }
    }
  }
  while (!data_.empty() && data_bytes_ + bytes > limits_.max_bytes) drop(data_.begin());
  dropped_ += dropped;
  data_bytes_ += bytes;
  ++queued_by_subscription_[subscription_id];
  data_.push_back({subscription_id, std::move(message)});
  return dropped;
}

void ClientQueue::RemoveSubscription(uint32_t subscription_id) {
  std::lock_guard lock(mutex_);
  for (auto it = data_.begin(); it != data_.end();) {
    if (it->subscription_id == subscription_id) {
      data_bytes_ -= it->message->payload.size();
      --queued_by_subscription_[subscription_id];
      it = data_.erase(it);
    } else {
      ++it;
    }
  }
}

std::optional<OutgoingFrame> ClientQueue::Pop() {
  std::lock_guard lock(mutex_);
  if (!control_.empty()) {
    OutgoingFrame f = std::move(control_.front());
    control_.pop_front();
    if (f.kind == OutgoingFrame::Kind::kBinary) time_queued_ = false;
    return f;
  }
  if (data_.empty()) return std::nullopt;
  OutgoingFrame f;
  f.kind = OutgoingFrame::Kind::kMessageData;
  f.subscription_id = data_.front().subscription_id;
  f.message = std::move(data_.front().message);
  data_bytes_ -= f.message->payload.size();
  --queued_by_subscription_[f.subscription_id];
  data_.pop_front();
  ++sent_;
  return f;
}

bool ClientQueue::Overflowed() const {
  std::lock_guard lock(mutex_);
  return overflowed_;
}

uint64_t ClientQueue::dropped() const {
  std::lock_guard lock(mutex_);
  return dropped_;
}

std::map<uint32_t, uint64_t> ClientQueue::dropped_by_channel() const {
  std::lock_guard lock(mutex_);
  return dropped_by_channel_;
}

uint64_t ClientQueue::sent() const {
  std::lock_guard lock(mutex_);
  return sent_;
}

size_t ClientQueue::queued_messages() const {
  std::lock_guard lock(mutex_);
  return data_.size();
}

size_t ClientQueue::queued_bytes() const {
  std::lock_guard lock(mutex_);
  return data_bytes_;
}

}  // namespace probeless::foxglove
