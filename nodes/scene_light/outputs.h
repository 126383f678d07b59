// scene_light's publishers: scene/light, and scene/transfer and scene/indirect (created with the
// first frame that has one, re-created when a frame needs more bytes than the slots hold).
#pragma once

#include <cstddef>
#include <optional>

#include "probeless/bus/bus.h"
#include "probeless/light/pipeline.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/growing_publisher.h"
#include "probeless/node/node.h"

namespace probeless::scene_light {

class SceneOutputs {
 public:
  // Creates the scene/light publisher; `publish_transfer`: also scene/transfer for every frame.
  SceneOutputs(node::Node& node, bool publish_transfer);

  // Publishes a frame's results under `header` (the triggering message's): the light if the
  // estimate is valid (coefficients in the illuminant's colour, r.colour), the transfer if asked
  // for, the indirect light if the frame has one. Returns whether a light was published.
  bool Publish(const msgs::Header& header, const light::ScenePipelineResult& r);

 private:
  bool publish_transfer_;
  bus::Publisher light_pub_;
  node::GrowingPublisher<msgs::TransferBuffer> transfer_pub_;
  node::GrowingPublisher<msgs::Image> indirect_pub_;
};

}  // namespace probeless::scene_light
