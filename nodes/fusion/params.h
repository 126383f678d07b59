// fusion's params (docs/nodes.md, "fusion"): the one place the node reads them, so main.cpp is
// the graph plumbing only.
#pragma once

#include <string>

#include "probeless/node/node.h"
#include "probeless/recon/pipeline.h"

namespace probeless::fusion {

// Every fusion param, as the node's setup uses them (the defaults are ReadParams's).
struct FusionParams {
  recon::FusionOptions options;    // the pipeline's (volume, merge, ICP, normals)
  std::string mesh_out;            // PLY written at exit; empty: none
  std::string world_frame;         // header.frame_id of the world-frame outputs
  bool publish_aux = false;        // the auxiliary orthographic views on scene/aux
  int aux_pixels = 128;            // their side, pixels
  bool aux_light = false;          // a view along scene/light's direction
  double fail_on_lost_ratio = -1;  // exit 3 above this ratio of lost frames; < 0: never
  std::string checkpoint_path;     // the map's checkpoint file; empty: none
  int checkpoint_frames = 30;      // integrated frames between checkpoints
};

// Reads every fusion param of `node` (defaults: docs/nodes.md). Throws node::NodeError for a value
// outside a param's declared range or choices or a list of the wrong length.
FusionParams ReadParams(node::Node& node);

}  // namespace probeless::fusion
