// light_fusion: one light from the face and scene estimates, weighted by their confidences
// (light::FuseLights; beyond both papers). Subscribes face/light and scene/light (msgs::ShLight,
// linear radiance, the same frame, e.g. the camera frame, confidences on the ShLight scale:
// c = 1 / (1 + (expected error / 10 deg)^2)); after each input publishes `light`, the fusion of
// the latest of each. Params: max_age_s (0.5: an input that much older than the newest is
// ignored), min_confidence (0.05), consistency_sigma (3: the less confident of two inputs further
// apart than that many combined expected errors is left out; 0 = off), face_units / scene_units
// (linear | relative: what the producer publishes; a relative input is refused with one warning,
// never averaged), face_calibration / scene_calibration ([] = on the scale; else pairs raw
// confidence, expected error in degrees: light::ConfidenceCalibration). Exit: 0 on SIGINT/SIGTERM,
// 2 on bad params, 1 otherwise.
#include "probeless/node/main.h"

#include <optional>
#include <string>

#include "probeless/light/fusion.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/node/node.h"

namespace {

using namespace probeless;

light::LightUnits Units(const std::string& name, const std::string& value) {
  if (value == "linear") return light::LightUnits::kLinear;
  if (value == "relative") return light::LightUnits::kRelative;
  throw node::UsageError("param " + name + " must be linear or relative, got '" + value + "'");
}

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "light_fusion");
  light::FusionOptions options;
  const double max_age_s = node.Param("max_age_s", 0.5);
  if (!(max_age_s > 0)) throw node::UsageError("param max_age_s must be > 0");
  options.max_age_ns = static_cast<int64_t>(max_age_s * 1e9);
  options.min_confidence = static_cast<float>(node.Param("min_confidence", 0.05));
  options.consistency_sigma = node.Param("consistency_sigma", options.consistency_sigma);
  if (!(options.consistency_sigma >= 0)) {
    throw node::UsageError("param consistency_sigma must be >= 0");
  }
  const light::LightUnits units[2] = {
      Units("face_units", node.Param("face_units", std::string("linear"))),
      Units("scene_units", node.Param("scene_units", std::string("linear")))};
  // Raw confidences onto the ShLight scale, per input (empty = already on it).
  const light::ConfidenceCalibration calibration[2] = {
      light::ConfidenceCalibration(node.Param("face_calibration", std::vector<double>{})),
      light::ConfidenceCalibration(node.Param("scene_calibration", std::vector<double>{}))};
  bus::Subscriber face = node.CreateSubscriber<msgs::ShLight>("face/light", {.queue_depth = 4});
  bus::Subscriber scene = node.CreateSubscriber<msgs::ShLight>("scene/light", {.queue_depth = 4});
  bus::Publisher out = node.CreatePublisher<msgs::ShLight>("light");
  const std::string names[2] = {face.topic(), scene.topic()};
  std::optional<msgs::ShLight> latest[2];
  bool warned[2] = {false, false};
  uint64_t published = 0;
  auto handler = [&](int which) {
    return [&, which](bus::Sample&& sample) {
      latest[which] = *msgs::ReadMessage<msgs::ShLight>(sample.data());
      std::vector<light::FusionInput> inputs;
      for (int k = 0; k < 2; ++k) {
        if (!latest[k]) continue;
        if (units[k] != light::LightUnits::kLinear) {
          // Refused, never averaged raw: the other input is still followed.
          if (!warned[k]) {
            node.Warn() << names[k] << " is declared in relative units (" << (k ? "scene" : "face")
                        << "_units); it is refused, only linear lights are fused";
            warned[k] = true;
          }
          continue;
        }
        light::FusionInput input{*latest[k], units[k], names[k]};
        input.light.confidence = static_cast<float>(calibration[k].Apply(input.light.confidence));
        inputs.push_back(input);
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
