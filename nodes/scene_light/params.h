// scene_light's params (docs/nodes.md, "scene_light") as the pipeline's options; main.cpp reads
// only the node's own (mode, publish_transfer, use_aux, aux_wait_ms, focus).
#pragma once

#include <string>

#include "probeless/light/pipeline.h"
#include "probeless/node/node.h"

namespace probeless::scene_light {

// The pipeline options of `node`'s params for `mode` ("gbuffer" or "depth", already checked).
// Throws node::NodeError for a value outside a param's declared range or choices, node::UsageError
// for a combination the pipeline refuses (temporal_frames > 1 with an explicit light_model other
// than distant, and the like).
light::ScenePipelineOptions OptionsFromParams(node::Node& node, const std::string& mode);

}  // namespace probeless::scene_light
