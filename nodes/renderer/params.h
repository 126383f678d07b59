// The renderer's params (docs/nodes.md, "renderer"): the one place the node reads them, so
// main.cpp is the graph plumbing only.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "probeless/node/node.h"
#include "probeless/render/content.h"
#include "probeless/render/differential.h"
#include "probeless/render/renderer.h"

namespace probeless::renderer_node {

// Every renderer param, as the node's setup uses them (the defaults are ReadParams's).
struct RendererParams {
  std::string mode;                          // "face" or "scene"
  render::ContentOptions content_options;    // the objects, their anchor, the bake
  bool gbuffer_differential = false;         // shadows and bounce from G_r (no receiver mesh)
  bool face_differential = false;            // ... in face mode, from the proxy head at its pose
  render::DifferentialOptions diff_options;  // shadows and bounce from G_r (eq. 13-15)
  std::vector<double> object_pixel;          // [u, v] placement in scene mode; empty: none
  std::string trigger;                       // "light" or "image": what renders a frame
  render::RendererOptions renderer_options;  // back-end and tone mapping
  std::string video;                         // video file; empty: none
  double video_fps = 30;                     // Hz
  std::string png_dir;                       // PNG frames; empty: none
  int64_t max_frames = 0;                    // exit after this many composites; 0: never
  // The virtual objects shaded with the light's expected value under its own direction
  // uncertainty (light::UncertaintyBandFactor of the message's confidence, this blur); the G_r
  // differential keeps the light as published (a baked receiver and a scene/transfer input get
  // the blurred light too). Needs a calibrated confidence. 0: off.
  double object_uncertainty_blur = 0;
};

// Reads every renderer param of `node` (defaults: docs/nodes.md). Throws node::NodeError for a
// value outside a param's declared range or choices, render::RenderError for a list of the wrong
// length, a placement the mode does not take or an unknown backend name.
RendererParams ReadParams(node::Node& node);

}  // namespace probeless::renderer_node
