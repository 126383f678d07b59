// light_fusion: one light from the face and scene estimates, weighted by their confidences
// (light::FuseLights; beyond both papers). Subscribes face/light and scene/light (msgs::ShLight,
// the same frame, e.g. the camera frame); after each input publishes `light`, the fusion of the
// latest of each. Params: max_age_s (0.5: an input that much older than the newest is ignored),
// min_confidence (0.05). Exit: 0 on SIGINT/SIGTERM, 2 on bad params, 1 otherwise.
#include "probeless/node/main.h"

#include <optional>

#include "probeless/light/fusion.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/node/node.h"

namespace {

using namespace probeless;

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "light_fusion");
  light::FusionOptions options;
  const double max_age_s = node.Param("max_age_s", 0.5);
  if (!(max_age_s > 0)) throw node::UsageError("param max_age_s must be > 0");
  options.max_age_ns = static_cast<int64_t>(max_age_s * 1e9);
  options.min_confidence = static_cast<float>(node.Param("min_confidence", 0.05));
  bus::Subscriber face = node.CreateSubscriber<msgs::ShLight>("face/light", {.queue_depth = 4});
  bus::Subscriber scene = node.CreateSubscriber<msgs::ShLight>("scene/light", {.queue_depth = 4});
  bus::Publisher out = node.CreatePublisher<msgs::ShLight>("light");
  std::optional<msgs::ShLight> latest[2];
  uint64_t published = 0;
  auto handler = [&](int which) {
    return [&, which](bus::Sample&& sample) {
      latest[which] = *msgs::ReadMessage<msgs::ShLight>(sample.data());
      std::vector<msgs::ShLight> inputs;
      for (const auto& l : latest) {
        if (l) inputs.push_back(*l);
      }
      try {
        if (const auto fused = light::FuseLights(inputs, options)) {
          out.PublishCopy(std::as_bytes(std::span(&*fused, 1)));
          ++published;
        }
      } catch (const light::FusionError& e) {
        node.Warn() << e.what();
      }
    };
  };
  node.Spin({{&face, handler(0)}, {&scene, handler(1)}});
  node.Info() << "published " << published << " fused lights";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain<probeless::light::FusionError>("light_fusion",
                                                                 [&] { return Run(argc, argv); });
}
