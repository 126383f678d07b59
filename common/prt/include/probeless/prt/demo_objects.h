// Procedural virtual objects shipped for demos and tests, built in the face frame of
// msgs::FaceObservation (origin at the nose bridge, x to the subject's left ear, y to the chin,
// z into the head; metres) so they sit on raytrace::MakeHead's head: the clown nose of Knorr &
// Kurz 2014 (fig. 1), a cap and glasses frames; plus the proxy head occluder (the grey head of
// K&K fig. 5) and a 50k-vertex benchmark scene.
#pragma once

#include <string>
#include <vector>

#include "probeless/raytrace/mesh.h"

namespace probeless::prt {

// The proxy head occluder: raytrace::MakeHead's mesh (face frame) at `resolution` (>= 8).
raytrace::Mesh ProxyHead(int resolution = 64);

// A red sphere of radius 0.022 m on the proxy head's nose tip (landmark 30), vertex colours set.
raytrace::Mesh MakeClownNose(int segments = 48);
// A cap: an elliptic dome over the crown with a visor over the forehead, vertex colours set.
raytrace::Mesh MakeCap(int segments = 48);
// Glasses frames: two rings around the eyes, a bridge and two temples to the ears, dark colour.
raytrace::Mesh MakeGlasses(int segments = 32);
// A torus around the object z axis: `major` radius of the ring, `minor` radius of the tube.
raytrace::Mesh MakeTorus(float major, float minor, int segments_major, int segments_minor);

// Names accepted by MakeDemoObject: "nose", "cap", "glasses".
std::vector<std::string> DemoObjectNames();
// The demo object called `name`. Throws PrtError for any other name.
raytrace::Mesh MakeDemoObject(const std::string& name);

// The benchmark scene of `prt_bake --benchmark`: a sphere subdivided to about `vertices`
// vertices (>= 100) sitting on a ground plate, in the face frame next to the proxy head.
raytrace::Mesh MakeBenchmarkObject(int vertices = 50000);

}  // namespace probeless::prt
