// face_tracker: detects and tracks a face, estimates its head pose and samples a face_light
// model's positions on it (docs/face_light.md, "face_tracker node").
//
// Subscribes `image` (msgs::Image rgb8 / bgr8 / mono8) and `camera_info` (msgs::CameraInfo,
// optional: intrinsics for the head pose; without it a 60-degree guess; a pinhole: with lens
// distortion it warns once, launch files feed the rectify node's image_rect / camera_info_rect).
// Publishes `face/observation` (msgs::FaceObservation) for every image (face_detected = 0 when
// none) and, with publish_debug_image, `face/debug_image` (rgb8, samples drawn: paper figure 1c).
//
// Params: backend (dlib | yunet | haar), shape_predictor_path, yunet_model_path,
// haar_cascade_path, redetect_period, detect_max_width, pose_smoothing, flow_tracking (true),
// clahe_clip_limit (4; 0 = off), max_undetected_frames (150), sample_model (default
// data/face_light/default_model.txt: absolute, else relative to the working directory, the source
// tree, then <prefix>/share/probeless), saturation_level, dark_level, min_facing_cosine,
// neighbour_threshold, four_point_frame, publish_debug_image, image_transfer (linear: sample
// values as they are, like the Yale B training images | srgb: decode sRGB images (webcams, sim)).
// Exit: 0 on SIGINT/SIGTERM, 2 on bad params or models (one line on stderr), 1 otherwise.
#include "probeless/node/main.h"

#include <algorithm>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "probeless/face_light/model.h"
#include "probeless/face_track/face_tracker.h"
#include "probeless/face_track/sampling.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/data_file.h"
#include "probeless/node/growing_publisher.h"
#include "probeless/node/node.h"

namespace {

using namespace probeless;
namespace ft = probeless::face_track;

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "face_tracker");
  ft::TrackerOptions options;
  options.backend = ft::BackendFromName(node.Param("backend", "dlib"));
  options.shape_predictor_path = node.Param("shape_predictor_path", ft::kDefaultShapePredictorPath);
  options.yunet_model_path = node.Param("yunet_model_path", "");
  options.haar_cascade_path = node.Param("haar_cascade_path", ft::kDefaultHaarCascadePath);
  options.redetect_period = node.Param("redetect_period", options.redetect_period);
  options.detect_max_width = node.Param("detect_max_width", options.detect_max_width);
  options.pose_smoothing = node.Param("pose_smoothing", options.pose_smoothing);
  options.flow_tracking = node.Param("flow_tracking", options.flow_tracking);
  options.clahe_clip_limit = node.Param("clahe_clip_limit", options.clahe_clip_limit);
  options.max_undetected_frames =
      node.Param("max_undetected_frames", options.max_undetected_frames);
  ft::SamplerOptions sampler_options;
  sampler_options.saturation_level =
      node.Param("saturation_level", sampler_options.saturation_level);
  sampler_options.dark_level = node.Param("dark_level", sampler_options.dark_level);
  sampler_options.min_facing_cosine =
      node.Param("min_facing_cosine", sampler_options.min_facing_cosine);
  sampler_options.neighbour_threshold =
      node.Param("neighbour_threshold", sampler_options.neighbour_threshold);
  sampler_options.four_point_frame =
      node.Param("four_point_frame", sampler_options.four_point_frame);
  sampler_options.srgb_input =
      node.Param("image_transfer", "linear", {.choices = {"linear", "srgb"}}) == "srgb";
  const bool debug_image = node.Param("publish_debug_image", false);
  const std::string model_path =
      node::ResolveDataFile(node.Param("sample_model", "data/face_light/default_model.txt"));

  const face_light::FaceLightModel model = face_light::LoadModel(model_path);
  ft::FaceTracker tracker(options);
  const ft::FaceSampler sampler(model, sampler_options);
  node.Info() << "sampling " << sampler.SampleCount() << " positions of " << model_path;

  bus::Subscriber images = node.CreateSubscriber<msgs::Image>("image", {.queue_depth = 4});
  bus::Subscriber infos =
      node.CreateSubscriber<msgs::CameraInfo>("camera_info", {.queue_depth = 4});
  bus::Publisher observations = node.CreatePublisher<msgs::FaceObservation>("face/observation");
  node::GrowingPublisher<msgs::Image> debug(node, "face/debug_image");
  std::optional<ft::Intrinsics> intrinsics;
  std::vector<uint8_t> drawn;
  int64_t frames = 0, found = 0;

  bool warned_distortion = false;
  auto on_info = [&](bus::Sample&& sample) {
    const auto info = msgs::ReadMessage<msgs::CameraInfo>(sample.data());
    // Landmarks, head pose and samples assume a pinhole: a lens must be rectified first.
    const bool distorted =
        std::any_of(info->distortion, info->distortion + std::min(info->distortion_count, 8u),
                    [](double d) { return d != 0; });
    if (distorted && !warned_distortion) {
      node.Warn() << node.ResolveTopicName("camera_info") << " has lens distortion ("
                  << msgs::DistortionModelName(info->distortion_model)
                  << "): landmarks and head pose assume a pinhole; feed the rectify node's "
                     "image_rect and camera_info_rect (docs/rectify.md; the launch files do)";
      warned_distortion = true;
    }
    if (info->fx > 0 && info->fy > 0)
      intrinsics = ft::Intrinsics{info->fx, info->fy, info->cx, info->cy};
  };
  auto on_image = [&](bus::Sample&& sample) {
    const auto image = msgs::ReadMessage<msgs::Image>(sample.data());
    const ft::ImageView view = ft::ViewOfImage(*image, image.payload);
    const ft::Intrinsics k =
        intrinsics ? *intrinsics : ft::Intrinsics::Guess(view.width, view.height);
    const ft::FaceTrack track = tracker.Track(view, k);
    std::optional<ft::FaceSamples> samples;
    if (track.found) samples = sampler.Sample(view, track);
    ++frames;
    found += track.found;

    bus::Loan loan = observations.Borrow(sizeof(msgs::FaceObservation));
    auto out = msgs::WriteMessage<msgs::FaceObservation>(loan.data());
    out->header = image->header;
    ft::FillObservation(track, samples ? &*samples : nullptr, *out);
    observations.Publish(std::move(loan));

    if (debug_image && track.found) {
      const size_t bytes =
          msgs::Image::MessageBytesFor(image->width, image->height, msgs::Encoding::kRgb8);
      ft::DrawDebugImage(view, track, *samples, k, drawn);
      bus::Loan dl = debug.Borrow(bytes);
      auto di = msgs::WriteMessage<msgs::Image>(dl.data());
      di->header = image->header;
      di->Init(image->width, image->height, msgs::Encoding::kRgb8);
      std::memcpy(di.payload.data(), drawn.data(), drawn.size());
      debug.Publish(std::move(dl));
    }
  };
  node.Spin({{&infos, on_info}, {&images, on_image}});
  node.Info() << "face found in " << found << " of " << frames << " frames ("
              << tracker.full_detections() << " full, " << tracker.region_detections()
              << " region detections)";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return node::RunMain("face_tracker", [&] { return Run(argc, argv); });
}
