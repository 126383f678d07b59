// A publisher whose message size is only known when the first message is made (an image of the
// camera's size, a G-buffer, a transfer buffer): created with the first Borrow and re-created,
// larger, when a message does not fit (iceoryx2's "dynamic" allocation strategy). Subscribers
// attach by topic and follow a re-created publisher (bus.h).
//
//   node::GrowingPublisher<msgs::Image> composite(node, "render/composite", {.slot_count = 8});
//   bus::Loan loan = composite.Borrow(msgs::Image::MessageBytesFor(w, h, msgs::Encoding::kRgb8));
//   ... fill it with msgs::WriteMessage<msgs::Image>(loan.data()) ...
//   composite.Publish(std::move(loan));
//
// Not thread-safe: one per topic and thread, like bus::Publisher.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <utility>

#include "probeless/bus/bus.h"
#include "probeless/error/error.h"
#include "probeless/node/node.h"

namespace probeless::node {

template <msgs::Message M>
class GrowingPublisher {
 public:
  // `topic` is resolved by `node` (remaps, namespace) when the publisher is created; `options`
  // apply to every creation except max_message_bytes, which is the largest message so far.
  // `node` must outlive this object.
  GrowingPublisher(Node& node, std::string topic, bus::PublisherOptions options = {})
      : node_(node), topic_(std::move(topic)), options_(options) {}

  // A loan of `bytes` (the whole message: header, fields and payload, e.g.
  // msgs::Image::MessageBytesFor). The first call creates the publisher with room for `bytes`; a
  // later one with more bytes than it has room for re-creates it with room for `bytes` (the old
  // one's unreleased samples stay valid to their readers). Throws as Node::CreatePublisher and
  // bus::Publisher::Borrow.
  bus::Loan Borrow(size_t bytes) {
    if (!publisher_ || bytes > publisher_->max_message_bytes()) {
      publisher_.reset();
      bus::PublisherOptions options = options_;
      options.max_message_bytes = bytes;
      publisher_.emplace(node_.CreatePublisher<M>(topic_, options));
    }
    return publisher_->Borrow(bytes);
  }

  // Publishes a loan of the last Borrow (bus::Publisher::Publish); returns its sequence number.
  uint64_t Publish(bus::Loan&& loan) {
    PROBELESS_DEMAND(publisher_.has_value(), "GrowingPublisher::Publish before any Borrow");
    return publisher_->Publish(std::move(loan));
  }

  // Whether a message was borrowed yet (the publisher exists).
  bool created() const { return publisher_.has_value(); }

 private:
  Node& node_;
  std::string topic_;
  bus::PublisherOptions options_;
  std::optional<bus::Publisher> publisher_;
};

}  // namespace probeless::node
