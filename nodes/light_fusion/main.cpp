// light_fusion: one light from the face and scene estimates, weighted by their confidences
// (light::FuseLights; beyond both papers). Subscribes face/light and scene/light (msgs::ShLight,
// linear radiance, the same frame, e.g. the camera frame, confidences on the ShLight scale:
// c = 1 / (1 + (expected error / 10 deg)^2)); after each input publishes `light`, the fusion of
// the latest of each. Params: max_age_s (0.5: an input that much older than the newest is
// ignored), min_confidence (0.05), consistency_sigma (3: the less confident of two inputs further
// apart than that many combined expected errors is left out; 0 = off), face_units / scene_units
// (linear | face_model | linear_unscaled: the units taken for a message whose units field is
// unknown, i.e. one recorded before the field; default linear, what face_light and scene_light
// published then), face_calibration / scene_calibration ([] = on the scale; else pairs raw
// confidence, expected error in degrees: light::ConfidenceCalibration). An input in other than
// linear units is refused with one warning per input and units, never averaged (no conversion
// exists without the face's samples); the other input is still followed. The output is linear.
// Exit: 0 on SIGINT/SIGTERM, 2 on bad params, 1 otherwise.
#include "probeless/node/main.h"

#include <optional>
#include <string>
#include <utility>

#include "probeless/light/fusion.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/node/node.h"

namespace {

using namespace probeless;

msgs::ShLightUnits Units(const std::string& name, const std::string& value) {
  for (msgs::ShLightUnits u : {msgs::ShLightUnits::kLinear, msgs::ShLightUnits::kFaceModel,
                               msgs::ShLightUnits::kLinearUnscaled}) {
    if (msgs::ShLightUnitsName(u) == value) return u;
  }
  throw node::UsageError("param " + name + " must be linear, face_model or linear_unscaled, got '" +
                         value + "'");
}

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "light_fusion");
  light::FusionOptions options;
  const double max_age_s =
      node.Param("max_age_s", 0.5, {.unit = "s", .min = 0.0, .min_exclusive = true});
  options.max_age_ns = static_cast<int64_t>(max_age_s * 1e9);
  options.min_confidence = static_cast<float>(node.Param("min_confidence", 0.05));
  options.consistency_sigma =
      node.Param("consistency_sigma", options.consistency_sigma, {.min = 0.0});
  // For messages without a units field (logs recorded before it).
  const msgs::ShLightUnits unknown_as[2] = {
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
  // The units (and whether the message declared them) last warned about per input: a change
  // warns again.
  std::optional<std::pair<msgs::ShLightUnits, bool>> warned[2];
  uint64_t published = 0;
  auto handler = [&](int which) {
    return [&, which](bus::Sample&& sample) {
      latest[which] = *msgs::ReadMessage<msgs::ShLight>(sample.data());
      std::vector<light::FusionInput> inputs;
      for (int k = 0; k < 2; ++k) {
        if (!latest[k]) continue;
        light::FusionInput input{*latest[k], names[k]};
        const bool declared = input.light.units != msgs::ShLightUnits::kUnknown;
        if (!declared) input.light.units = unknown_as[k];
        if (input.light.units != msgs::ShLightUnits::kLinear) {
          // Refused, never averaged raw: the other input is still followed.
          const std::pair<msgs::ShLightUnits, bool> key{input.light.units, declared};
          if (warned[k] != key) {
            node.Warn() << names[k] << " is in " << msgs::ShLightUnitsName(input.light.units)
                        << " units ("
                        << (declared ? std::string("its units field")
                                     : std::string(k ? "scene" : "face") + "_units")
                        << "); it is refused, only linear lights are fused";
            warned[k] = key;
          }
          continue;
        }
        input.light.confidence = static_cast<float>(calibration[k].Apply(input.light.confidence));
        inputs.push_back(input);
      }
      // A FusionError (inputs that cannot be fused, e.g. in different frames) is one error line,
      // counted under this sample's topic (node::Node::Spin); both inputs stay the latest.
      if (const auto fused = light::FuseLights(inputs, options)) {
        out.PublishCopy(std::as_bytes(std::span(&*fused, 1)));
        ++published;
      }
    };
  };
  node.Spin({{&face, handler(0)}, {&scene, handler(1)}});
  node.Info() << "published " << published << " fused lights";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("light_fusion", [&] { return Run(argc, argv); });
}
