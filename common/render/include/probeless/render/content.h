// Virtual content for the renderer: demo objects, baked PRT files and OBJ/PLY meshes (baked at
// load time with the proxy head in face mode or a real-scene mesh in scene mode), and the shadow
// receiver for differential rendering (the proxy head or the scene mesh baked without and with the
// virtual objects as occluders, K&K §4.2's "differential change" and Gruber eq. 13).
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

#include "probeless/prt/prt.h"
#include "probeless/render/renderer.h"

namespace probeless::render {

struct ContentOptions {
  Anchor anchor = Anchor::kFace;
  // Each entry: "nose", "cap", "glasses" (procedural demo objects, face frame), a .prt file (used
  // as baked), or an .obj/.ply mesh (baked now, in the anchor frame).
  std::vector<std::string> objects;
  // Scene mode: the real scene mesh (OBJ/PLY, world frame) used as occluder and receiver; empty =
  // none. Face mode always uses the proxy head.
  std::string scene_mesh;
  bool receiver = true;  // build the shadow receiver (virtual shadows on the face / scene)
  // Placement of every object before it is baked (so the scene mesh's occlusion and the receiver's
  // shadows see it where it is drawn): scaled by `object_scale` (> 0) about the centre of its
  // bounding box, then, when `object_position` is set, moved so that centre lands there (anchor
  // frame, metres; scene mode: the world frame of scene/pose). Defaults: as modelled.
  double object_scale = 1.0;
  std::optional<std::array<double, 3>> object_position;
  int head_resolution = 48;
  prt::BakeOptions bake;  // for meshes and demo objects baked at load time
};

struct Content {
  std::vector<VirtualObject> objects;
  std::optional<ShadowReceiver> receiver;
  std::vector<std::string> names;  // one per object, for logs
};

// Builds the content. Throws RenderError naming the entry for unknown names, missing or malformed
// files (e.g. "objects[1] 'x.obj': x.obj: cannot open OBJ file").
Content LoadContent(const ContentOptions& options);

}  // namespace probeless::render
