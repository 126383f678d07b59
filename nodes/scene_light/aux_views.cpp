#include "aux_views.h"

#include <utility>

#include "probeless/light/messages.h"

namespace probeless::scene_light {

AuxViewQueue::AuxViewQueue(node::Node& node, std::chrono::milliseconds wait)
    : node_(node),
      wait_(wait),
      sub_(node.CreateSubscriber<msgs::AuxiliaryViews>("scene/aux", {.queue_depth = 8})) {}

void AuxViewQueue::Hold(bus::Sample&& s) {
  queue_.push_back(std::move(s));
  if (queue_.size() > kKept) queue_.pop_front();
}

// The views with `stamp`: drops older ones, waits up to wait_ while none as new arrived.
std::optional<bus::Sample> AuxViewQueue::Take(int64_t stamp) {
  const auto deadline = std::chrono::steady_clock::now() + wait_;
  while (true) {
    // Acknowledged on receipt (they are taken outside Spin): the player's lock-step counts every
    // input of the node; the G_r that follows them is acknowledged by Spin after its frame.
    while (auto s = sub_.TryTake()) {
      node_.Ack(sub_, s->info());
      Hold(std::move(*s));
    }
    while (!queue_.empty()) {
      bus::Sample front = std::move(queue_.front());
      queue_.pop_front();
      // Throws MessageError for a sample shorter than the struct (then dropped).
      const int64_t front_stamp =
          msgs::ReadMessage<msgs::AuxiliaryViews>(front.data())->header.stamp_ns;
      if (front_stamp > stamp) {  // the G_r's views never came
        queue_.push_front(std::move(front));
        return std::nullopt;
      }
      if (front_stamp == stamp) return front;
    }
    const auto now = std::chrono::steady_clock::now();
    if (now >= deadline) return std::nullopt;
    if (auto s = sub_.Take(deadline - now)) {
      node_.Ack(sub_, s->info());
      Hold(std::move(*s));
    }
  }
}

void AuxViewQueue::ForFrame(const msgs::Header& header, FrameAuxViews* out) {
  try {
    out->sample = Take(header.stamp_ns);
    if (out->sample) {
      const auto m = msgs::ReadMessage<msgs::AuxiliaryViews>(out->sample->data());
      out->buffers = light::AuxiliaryFromMessage(*m, m.payload);
      ++used_;
    } else {
      if (missing_ == 0) {
        node_.Warn() << "no scene/aux for the G_r of stamp " << header.stamp_ns << " within "
                     << wait_.count() << " ms: frames without one run without auxiliary views";
      }
      ++missing_;
    }
  } catch (const msgs::MessageError& e) {
    node_.Error() << e.what() << " (frame " << header.sequence << " runs without auxiliary views)";
    out->buffers = {};
    ++bad_;
  }
}

void AuxViewQueue::LogSummary() const {
  node_.Info() << "auxiliary views: used for " << used_ << " frames, missing for " << missing_
               << ", malformed for " << bad_;
}

}  // namespace probeless::scene_light
