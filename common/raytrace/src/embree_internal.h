// Private Embree stream helpers shared by the scene queries and the renderer.
#pragma once

#include <embree3/rtcore.h>

#include <cstddef>

#include "probeless/raytrace/scene.h"

namespace probeless::raytrace::internal {

// Fills an Embree ray from `r` (mask all, time 0).
void ToEmbree(const Ray& r, RTCRay& out);
// rtcIntersect1M over `count` rays (hits reset first); `coherent` for camera rays.
void IntersectStream(RTCScene scene, RTCRayHit* rays, size_t count, bool coherent);
// rtcOccluded1M over `count` rays, `stride` bytes apart: an occluded ray gets tfar = -inf.
void OccludedStream(RTCScene scene, RTCRay* rays, size_t count, size_t stride = sizeof(RTCRay));

}  // namespace probeless::raytrace::internal
