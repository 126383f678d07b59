// fusion: real-time CPU KinectFusion and the image-space depth merge (Gruber et al. 2015 §4) as a
// node. A thin node: params -> recon::FusionOptions (params.h), messages -> recon::DepthFrame /
// recon::ColourFrame (recon/msgs_io.h), recon::FusionPipeline -> messages (outputs.h); the state
// between frames and the handlers are fusion::FusionNode (fusion_node.h). Subscribes camera/depth
// (depth16 or float32), camera/image (rgb8, bgr8 or mono8; used as the merge's intensity guidance,
// assumed registered to the depth), camera/camera_info and ~/reset (any probeless_msgs/Header:
// forget the map). Publishes, per frame and in this order,
// scene/tracking (TrackingStatus: the tracking-quality verdict, recon/tracking_quality.h, with
// running counts), scene/pose (camera -> world, parent param world_frame; tracked and uncertain
// frames only, none for a lost frame) and scene/gbuffer (G_r: merged depth, normals, colour;
// GeometryBuffer in the depth camera's frame; for uncertain and lost frames the raw depth merged
// without the volume). A change of the tracking state is logged once (a warning when it leaves
// "tracked", an info line when it comes back), not every frame. At shutdown one summary line
// on stdout: "fusion: frames=N tracked=T uncertain=U lost=L relocalised=R", plus a warning
// naming the lost share when L > 0.
//
// Params: volume_size (2.0 m), volume_resolution (256), volume_origin ([-1, -1.2, 0.5] m, in the
// first camera's frame), truncation (0.03 m), max_weight (64), threads (2), depth_min (0.3),
// depth_max (4.0), merge (true), merge_k (20), lambda_i (7), lambda_d (0.05 m), smooth_k (8),
// smooth_lambda_i (7), denoise_k (2), lambda_d_sigmas (3: the merge's agreement threshold is
// min(lambda_d, lambda_d_sigmas sigma(z)); 0 = the paper's lambda_d), depth_noise ([0.0012,
// 0.0019, 0.4]: sigma(z) = a + b (z - z0)^2 m), depth_quantisation (0 per m; see
// recon::MergeOptions), icp_iterations ([4, 5, 10], fine to coarse), mesh_out (""
// or a .ply path written at shutdown), world_frame ("world"), normals (G_r's normals: "depth" =
// from D''', "volume" = the TSDF gradient where D''' agrees with the volume; see
// recon::FusionOptions::normal_source), normal_gap (0.03 m), normal_gradient_step (1 voxel),
// publish_aux (false: publish the auxiliary orthographic views of §5.1 on scene/aux, an
// AuxiliaryViews with the G_r's header, before the G_r; left, right, top), aux_pixels (128 per
// side), aux_light (false: also the view from the light: subscribes scene/light, the ShLight
// scene_light publishes in the camera frame of a G_r, turns its dominant direction into the world
// with the pose of that G_r's stamp and adds the light view to every later frame's views). Reset:
// publish any probeless_msgs/Header on ~/reset (/fusion/reset). fail_on_lost_ratio (-1 = off):
// exit 3 at shutdown when lost / frames exceeds it (0: any lost frame). checkpoint ("" = off, or
// a file path): the map survives a restart - at start-up a checkpoint found there is resumed (the
// first frame relocalises against it; a file that is not a valid checkpoint for these volume
// params is a bad param, exit 2), every checkpoint_frames (30) integrated frames and at shutdown
// the map is written there atomically (recon/checkpoint.h, on a thread of its own), and a reset
// removes it.
//
// A frame is processed when its depth and its image (same header.stamp_ns) have both arrived, or
// on the depth alone when no image with that stamp comes before the next depth. Exit: 0 on
// SIGINT/SIGTERM, 3 then when fail_on_lost_ratio is exceeded, 2 on bad params (and a bad
// checkpoint), 1 otherwise (also when the checkpoint at shutdown cannot be written).
#include <cstdio>
#include <exception>

#include "fusion_node.h"
#include "params.h"
#include "probeless/node/node.h"
#include "probeless/recon/math.h"

namespace {

using namespace probeless;

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "fusion");
  const fusion::FusionParams params = fusion::ReadParams(node);
  fusion::FusionNode fusion_node(node, params);
  return fusion_node.Spin();
}

}  // namespace

// Not node::RunMain: its policy differs for InputErrors other than NodeError and ReconError and
// for std::invalid_argument (exit 2 there, 1 here).
int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const probeless::node::NodeError& e) {
    std::fprintf(stderr, "[error] [fusion] %s\n", e.what());
    return 2;
  } catch (const probeless::recon::ReconError& e) {
    std::fprintf(stderr, "[error] [fusion] %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [fusion] %s\n", e.what());
    return 1;
  }
}
