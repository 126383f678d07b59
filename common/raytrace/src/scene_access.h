// Private access of the path tracer to the scene: the Embree handle, the instance -> object map
// and whether any visible object emits (so emission-free scenes can skip work).
#pragma once

#include <embree3/rtcore.h>

#include "probeless/raytrace/scene.h"

namespace probeless::raytrace::internal {

struct SceneAccess {
  static RTCScene Handle(const Scene& scene);
  // The object index (Scene::AddObject) of a top-level instance id (RTCHit::instID[0]).
  static int ObjectOfInstance(const Scene& scene, unsigned inst_id);
  // Throws RaytraceError unless committed.
  static void CheckCommitted(const Scene& scene, const char* what);
  // Scene::Surface for a hit of the ray (origin, unit direction) in single precision (the path
  // tracer's hot path; Render keeps the double-precision Surface).
  static SurfacePoint Surface(const Scene& scene, const Hit& hit, Vec3 origin, Vec3 direction);
  // True if a visible object's material has emission > 0.
  static bool HasEmission(const Scene& scene);
};

}  // namespace probeless::raytrace::internal
