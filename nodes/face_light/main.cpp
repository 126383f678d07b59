// face_light: light estimation from face observations (Knorr & Kurz 2014, eq. 19) with the
// face_light estimator, rotated from the face frame into the camera frame by the head pose,
// optionally smoothed, exported as JSON (docs/face_light.md, "face_light node").
//
// Subscribes `face/observation` (msgs::FaceObservation); publishes `face/light` (msgs::ShLight,
// header and frame of the observation = the camera frame, units kLinear: the model's estimate
// converted by face_light::LinearLightConverter with the skin albedo compensated; confidence on
// the ShLight scale from the calibrated expected error) for every observation with a face and
// enough valid samples; a light below hold_confidence (unlit, backlit face) is replaced by the
// last confident one blending towards its ambient term (face_track::LightHold). A lock-step player
// can name this node although it subscribes no played topic: the player waits until the whole chain
// is idle (docs/replay.md).
//
// Params: model (default data/face_light/default_model.txt, resolved like face_tracker's
// sample_model), mode (rgb | gray), back_prior (0.1), ridge, robust, non_negative, weight_floor,
// directional_fit (true: dominant direction by the directional-light fit), directional_robust (0),
// smoothing (true), smoothing_alpha (0.3), change_threshold (0.35), json_path ("" = none),
// json_mode (frame: one JSON line per estimate appended to json_path | exit: the last estimate
// written on exit; needs linear_output), linear_output (true; false = the model's compressed
// units, msgs::ShLightUnits::kFaceModel, no hold),
// skin_albedo ([0.47, 0.32, 0.25] linear RGB), unit_scale (0.223), hold_confidence (0.1),
// hold_blend_s (2.0).
// Exit: 0 on SIGINT/SIGTERM, 2 on bad params or model (one line on stderr), 1 otherwise.
#include "probeless/node/main.h"

#include <algorithm>
#include <array>
#include <fstream>
#include <optional>
#include <string>

#include "probeless/face_light/model.h"
#include "probeless/face_track/face_light_pipeline.h"
#include "probeless/face_track/light_output.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/data_file.h"
#include "probeless/node/node.h"
namespace {

using namespace probeless;
namespace ft = probeless::face_track;
namespace fl = probeless::face_light;

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "face_light");
  const std::string model_path =
      node::ResolveDataFile(node.Param("model", "data/face_light/default_model.txt"));
  ft::FaceLightPipelineOptions po;
  po.gray = node.Param("mode", "rgb", {.choices = {"rgb", "gray"}}) == "gray";
  fl::EstimatorOptions& eo = po.estimator;
  eo.back_prior = node.Param("back_prior", 0.1);
  eo.ridge = node.Param("ridge", 0.0);
  eo.robust = node.Param("robust", false);
  eo.non_negative = node.Param("non_negative", false);
  eo.weight_floor = node.Param("weight_floor", 0.0);
  eo.directional_fit = node.Param("directional_fit", eo.directional_fit);
  eo.directional_robust = node.Param("directional_robust", eo.directional_robust);
  ft::SmootherOptions& so = po.smoother;
  so.enabled = node.Param("smoothing", true);
  so.alpha =
      node.Param("smoothing_alpha", so.alpha, {.min = 0.0, .max = 1.0, .min_exclusive = true});
  so.change_threshold =
      node.Param("change_threshold", so.change_threshold, {.min = 0.0, .min_exclusive = true});
  const std::string json_path = node.Param("json_path", "");
  const std::string json_mode = node.Param("json_mode", "frame", {.choices = {"frame", "exit"}});

  po.linear_output = node.Param("linear_output", true);
  if (!json_path.empty() && !po.linear_output) {
    throw node::UsageError(
        "face_light: json_path exports ARKit / WebXR light, which is linear radiance; it needs "
        "linear_output true");
  }
  fl::LinearLightOptions& lo = po.linear;
  const std::vector<double> albedo =
      node.Param("skin_albedo", std::vector<double>(lo.skin_albedo.begin(), lo.skin_albedo.end()));
  if (albedo.size() != 3) {
    throw node::UsageError("face_light: skin_albedo must hold 3 values (linear R, G, B), got " +
                           std::to_string(albedo.size()));
  }
  std::copy(albedo.begin(), albedo.end(), lo.skin_albedo.begin());
  lo.unit_scale = node.Param("unit_scale", lo.unit_scale);
  ft::HoldOptions& ho = po.hold;
  ho.min_confidence = node.Param("hold_confidence", ho.min_confidence, {.min = 0.0, .max = 1.0});
  ho.blend_time_s =
      node.Param("hold_blend_s", ho.blend_time_s, {.unit = "s", .min = 0.0, .min_exclusive = true});

  // Bad model files and options throw FaceLightError (an InputError: exit 2).
  ft::FaceLightPipeline pipeline(fl::LoadModel(model_path), po);
  std::ofstream json;
  if (!json_path.empty() && json_mode == "frame") {
    json.open(json_path, std::ios::trunc);
    if (!json) throw node::UsageError("face_light: cannot write json_path '" + json_path + "'");
  }
  std::string last_json;

  bus::Subscriber observations =
      node.CreateSubscriber<msgs::FaceObservation>("face/observation", {.queue_depth = 64});
  bus::Publisher lights = node.CreatePublisher<msgs::ShLight>("face/light");
  int64_t received = 0, published = 0;

  auto on_observation = [&](bus::Sample&& sample) {
    const auto obs = msgs::ReadMessage<msgs::FaceObservation>(sample.data());
    obs->Validate();
    ++received;
    if (obs->face_detected && static_cast<int>(obs->sample_count) != pipeline.SampleCount()) {
      // Two models configured apart: no later observation can fit either, so the node ends.
      throw node::NodeError("face_light: observation has " + std::to_string(obs->sample_count) +
                            " samples but model '" + model_path + "' has " +
                            std::to_string(pipeline.SampleCount()) +
                            " (the tracker must sample the same model)");
    }
    const std::optional<msgs::ShLight> light = pipeline.Process(*obs);
    if (!light) return;
    lights.PublishCopy(std::as_bytes(std::span(&*light, 1)));
    ++published;
    if (!json_path.empty()) {
      ft::Sh9Rgb camera{};
      for (int n = 0; n < 9; ++n) std::copy_n(light->coefficients[n], 3, camera[n].begin());
      last_json = ft::LightJson(camera, std::to_array(light->dominant_direction), light->intensity,
                                light->confidence, ft::LightColour(camera), light->header.stamp_ns,
                                std::string(light->header.FrameId()), light->units);
      if (json_mode == "frame") json << last_json << '\n' << std::flush;
    }
  };
  std::vector<node::Handler> handlers{{&observations, on_observation}};
  node.Spin(handlers);
  if (!json_path.empty() && json_mode == "exit") {
    std::ofstream out(json_path, std::ios::trunc);
    out << (last_json.empty() ? "null" : last_json) << '\n';
  }
  node.Info() << "published " << published << " lights for " << received << " observations";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return node::RunMain("face_light", [&] { return Run(argc, argv); });
}
