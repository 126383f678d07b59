#include "params.h"

#include <vector>

#include "probeless/msgs/msgs.h"

namespace probeless::fusion {

FusionParams ReadParams(node::Node& node) {
  FusionParams p;
  recon::FusionOptions& options = p.options;
  options.volume.size_m = static_cast<float>(node.Param("volume_size", 2.0));
  options.volume.resolution = node.Param("volume_resolution", 256);
  const std::vector<double> origin =
      node.Param("volume_origin", std::vector<double>{-1, -1.2, 0.5});
  if (origin.size() != 3) throw node::NodeError("fusion: param volume_origin needs 3 values");
  options.volume.origin = {static_cast<float>(origin[0]), static_cast<float>(origin[1]),
                           static_cast<float>(origin[2])};
  options.volume.truncation_m = static_cast<float>(node.Param("truncation", 0.03));
  options.volume.max_weight = node.Param("max_weight", 64);
  options.threads = node.Param("threads", 2);
  options.preprocess.depth_min_m = static_cast<float>(node.Param("depth_min", 0.3));
  options.preprocess.depth_max_m = static_cast<float>(node.Param("depth_max", 4.0));
  options.merge_enabled = node.Param("merge", true);
  options.merge.merge_k = node.Param("merge_k", 20);
  options.merge.merge_lambda_i = static_cast<float>(node.Param("lambda_i", 7.0));
  options.merge.lambda_d_m = static_cast<float>(node.Param("lambda_d", 0.05));
  options.merge.smooth_k = node.Param("smooth_k", 8);
  options.merge.smooth_lambda_i = static_cast<float>(node.Param("smooth_lambda_i", 7.0));
  options.merge.denoise_k = node.Param("denoise_k", 2);
  options.merge.lambda_d_sigmas =
      static_cast<float>(node.Param("lambda_d_sigmas", double{options.merge.lambda_d_sigmas}));
  {
    const std::vector<double> noise = node.Param(
        "depth_noise", std::vector<double>{options.merge.noise_a_m, options.merge.noise_b_per_m,
                                           options.merge.noise_z0_m});
    if (noise.size() != 3) throw node::NodeError("fusion: param depth_noise needs 3 values");
    options.merge.noise_a_m = static_cast<float>(noise[0]);
    options.merge.noise_b_per_m = static_cast<float>(noise[1]);
    options.merge.noise_z0_m = static_cast<float>(noise[2]);
  }
  options.merge.noise_quantisation_per_m = static_cast<float>(
      node.Param("depth_quantisation", double{options.merge.noise_quantisation_per_m}));
  options.icp.iterations.clear();
  for (int64_t n : node.Param("icp_iterations", std::vector<int64_t>{4, 5, 10})) {
    options.icp.iterations.push_back(static_cast<int>(n));
  }
  {
    const bool volume_default = options.normal_source == recon::NormalSource::kVolume;
    const std::string normals = node.Param("normals", volume_default ? "volume" : "depth",
                                           {.choices = {"depth", "volume"}});
    options.normal_source =
        normals == "volume" ? recon::NormalSource::kVolume : recon::NormalSource::kDepth;
  }
  options.volume_normal_max_gap_m =
      static_cast<float>(node.Param("normal_gap", double{options.volume_normal_max_gap_m}));
  options.volume_normal_step_voxels = static_cast<float>(
      node.Param("normal_gradient_step", double{options.volume_normal_step_voxels}));
  p.mesh_out = node.Param("mesh_out", "");
  p.world_frame = node.Param("world_frame", "world");
  p.publish_aux = node.Param("publish_aux", false);
  p.aux_pixels = node.Param(
      "aux_pixels", 128, {.unit = "px", .min = 1.0, .max = double{msgs::kMaxAuxiliaryViewPixels}});
  p.aux_light = node.Param("aux_light", false);
  p.fail_on_lost_ratio = node.Param("fail_on_lost_ratio", -1.0);
  p.checkpoint_path = node.Param("checkpoint", "");
  p.checkpoint_frames = node.Param("checkpoint_frames", 30, {.min = 1.0});
  return p;
}

}  // namespace probeless::fusion
