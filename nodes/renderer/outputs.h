// The renderer's output topic.
#pragma once

#include <cstdint>

#include "probeless/bus/bus.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/growing_publisher.h"
#include "probeless/node/node.h"
#include "probeless/render/renderer.h"

namespace probeless::renderer_node {

// render/composite (Image rgb8): created with the first frame (its size is the camera's),
// re-created when a frame is larger; 8 slots, a history of the last two composites for
// subscribers that discover the topic a moment later (the recorder polls).
class CompositePublisher {
 public:
  // `node` must outlive this object.
  explicit CompositePublisher(node::Node& node)
      : publisher_(node, "render/composite", {.slot_count = 8, .history = 2}) {}
  // Publishes the width x height `composite` under `header` (the camera image's).
  void Publish(const msgs::Header& header, int width, int height,
               const render::Composite& composite);

 private:
  node::GrowingPublisher<msgs::Image> publisher_;
};

}  // namespace probeless::renderer_node
