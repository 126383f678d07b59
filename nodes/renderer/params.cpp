#include "params.h"

#include <string>
#include <vector>

namespace probeless::renderer_node {

RendererParams ReadParams(node::Node& node) {
  RendererParams p;
  render::ContentOptions& content_options = p.content_options;
  p.mode = node.Param("mode", "face", {.choices = {"face", "scene"}});
  const std::string& mode = p.mode;
  content_options.anchor = mode == "face" ? render::Anchor::kFace : render::Anchor::kWorld;
  content_options.objects = node.Param<std::vector<std::string>>("objects", {"nose"});
  content_options.object_scale = node.Param("object_scale", 1.0);
  const std::vector<double> position = node.Param("object_position", std::vector<double>{});
  if (!position.empty()) {
    if (position.size() != 3) {
      throw render::RenderError("param object_position: expected [x, y, z] (metres), got " +
                                std::to_string(position.size()) + " values");
    }
    content_options.object_position = {position[0], position[1], position[2]};
  }
  content_options.scene_mesh = node.Param("scene_mesh", "");
  const bool shadows = node.Param("shadows", true);
  // Face mode keeps the ray-traced proxy-head receiver unless asked for G_r'.
  const std::string shadow_source = node.Param("shadow_source", mode == "face" ? "mesh" : "gbuffer",
                                               {.choices = {"gbuffer", "mesh"}});
  // The objects' shadows and bounce light from G_r (no receiver mesh; scene_mesh then only
  // occludes the bake): scene mode from fusion's G_r, face mode from the proxy head rasterised at
  // the head pose; shadow_source mesh asks for the baked receiver instead.
  p.gbuffer_differential = shadows && shadow_source == "gbuffer";
  p.face_differential = p.gbuffer_differential && mode == "face";
  content_options.receiver = shadows && !p.gbuffer_differential;
  render::DifferentialOptions& diff_options = p.diff_options;
  // The face is ~0.2 m across: a scene-sized radius would reach past it.
  diff_options.transfer.radius_m =
      static_cast<float>(node.Param("ssdo_radius", mode == "face" ? 0.1 : 0.3));
  diff_options.transfer.max_occluder_distance_m = 2 * diff_options.transfer.radius_m;
  diff_options.transfer.directions = node.Param("ssdo_directions", 32);
  diff_options.transfer.bands = node.Param("ssdo_bands", 4);
  diff_options.transfer.seed = static_cast<uint64_t>(node.Param<int64_t>("ssdo_seed", 1));
  diff_options.transfer.threads = node.Param("ssdo_threads", 2);
  diff_options.step = node.Param("differential_step", 2);
  diff_options.smooth_radius = node.Param("differential_smooth", 2);
  const std::string diff_tone =
      node.Param("differential_tone", "ratio", {.choices = {"fixed", "key", "ratio"}});
  diff_options.tone = diff_tone == "key"     ? render::DifferentialTone::kAverageKey
                      : diff_tone == "ratio" ? render::DifferentialTone::kRatio
                                             : render::DifferentialTone::kFixed;
  diff_options.key = static_cast<float>(node.Param("differential_key", 0.18));
  // The crisp shadow divides by R_d: only with the ratio tone (an explicit true with another tone
  // is the RenderError of DifferentialRenderer).
  diff_options.sun_shadow =
      node.Param("sun_shadow", diff_options.tone == render::DifferentialTone::kRatio);
  diff_options.indirect = node.Param("indirect", true);
  // A bake with scene_mesh (scene mode) or the proxy head (face mode) as occluder already has the
  // real scene's shadows on the objects.
  diff_options.virtual_occlusion =
      node.Param("virtual_occlusion", mode == "scene" && content_options.scene_mesh.empty());
  diff_options.virtual_bounce = node.Param("virtual_bounce", true);
  p.object_pixel = node.Param("object_pixel", std::vector<double>{});
  if (!p.object_pixel.empty() && (p.object_pixel.size() != 2 || mode != "scene")) {
    throw render::RenderError("param object_pixel: expected [u, v] (pixels) in scene mode, got " +
                              std::to_string(p.object_pixel.size()) + " values in " + mode +
                              " mode");
  }
  content_options.bake.samples = node.Param("samples", 256);
  content_options.bake.bands = node.Param("bands", 3);
  render::RendererOptions& renderer_options = p.renderer_options;
  renderer_options.backend = render::BackendFromName(node.Param("backend", "offscreen"));
  p.trigger = node.Param("trigger", "light", {.choices = {"light", "image"}});
  const std::string tone = node.Param("tone", "reinhard", {.choices = {"clamp", "reinhard"}});
  renderer_options.tone.op =
      tone == "reinhard" ? render::ToneOperator::kReinhard : render::ToneOperator::kClamp;
  renderer_options.tone.exposure = static_cast<float>(node.Param("exposure", 1.0));
  renderer_options.tone.white = static_cast<float>(node.Param("white", 4.0));
  p.video = node.Param("video", "");
  p.video_fps = node.Param("video_fps", 30.0, {.unit = "Hz", .min = 0.0, .min_exclusive = true});
  p.png_dir = node.Param("png_dir", "");
  p.max_frames = node.Param<int64_t>("max_frames", 0, {.min = 0.0});
  p.object_uncertainty_blur = node.Param("object_uncertainty_blur", 0.0, {.min = 0.0});
  return p;
}

}  // namespace probeless::renderer_node
