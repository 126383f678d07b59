#include "probeless/render/content.h"

#include <algorithm>
#include <cctype>
#include <string>

#include "probeless/prt/demo_objects.h"

namespace probeless::render {

namespace {

std::string Extension(const std::string& path) {
  const size_t dot = path.find_last_of('.');
  std::string ext = dot == std::string::npos ? "" : path.substr(dot + 1);
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return ext;
}

// Scales `mesh` about its bounding-box centre and moves that centre to `position` (if set).
void Place(raytrace::Mesh& mesh, double scale,
           const std::optional<std::array<double, 3>>& position) {
  if (scale == 1.0 && !position) return;
  const auto [lo, hi] = mesh.Bounds();
  const raytrace::Vec3 centre{(lo.x + hi.x) / 2, (lo.y + hi.y) / 2, (lo.z + hi.z) / 2};
  const raytrace::Vec3 target = position ? raytrace::Vec3{static_cast<float>((*position)[0]),
                                                          static_cast<float>((*position)[1]),
                                                          static_cast<float>((*position)[2])}
                                         : centre;
  const auto s = static_cast<float>(scale);
  for (raytrace::Vec3& p : mesh.positions) {
    p = {target.x + s * (p.x - centre.x), target.y + s * (p.y - centre.y),
         target.z + s * (p.z - centre.z)};
  }
}

}  // namespace

Content LoadContent(const ContentOptions& options) {
  if (!(options.object_scale > 0)) {
    throw RenderError("object_scale must be > 0, got " + std::to_string(options.object_scale));
  }
  Content content;
  std::vector<prt::Occluder> occluders;
  raytrace::Mesh real_mesh;
  if (options.anchor == Anchor::kFace) {
    real_mesh = prt::ProxyHead(options.head_resolution);
  } else if (!options.scene_mesh.empty()) {
    try {
      real_mesh = raytrace::LoadMesh(options.scene_mesh);
    } catch (const std::exception& e) {
      throw RenderError("scene mesh '" + options.scene_mesh + "': " + e.what());
    }
  }
  if (!real_mesh.positions.empty()) occluders.push_back({real_mesh, {}});

  for (size_t i = 0; i < options.objects.size(); ++i) {
    const std::string& entry = options.objects[i];
    const std::string label = "objects[" + std::to_string(i) + "] '" + entry + "'";
    try {
      VirtualObject object;
      object.anchor = options.anchor;
      const auto names = prt::DemoObjectNames();
      if (std::find(names.begin(), names.end(), entry) != names.end()) {
        raytrace::Mesh mesh = prt::MakeDemoObject(entry);
        Place(mesh, options.object_scale, options.object_position);
        object.mesh = prt::Bake(mesh, occluders, options.bake);
      } else if (Extension(entry) == "prt") {
        object.mesh = prt::LoadPrt(entry);  // self-occlusion survives scale and translation
        Place(object.mesh.mesh, options.object_scale, options.object_position);
      } else if (Extension(entry) == "obj" || Extension(entry) == "ply") {
        raytrace::Mesh mesh = raytrace::LoadMesh(entry);
        Place(mesh, options.object_scale, options.object_position);
        object.mesh = prt::Bake(mesh, occluders, options.bake);
      } else {
        throw RenderError("expected nose, cap, glasses or a .prt, .obj or .ply file");
      }
      content.objects.push_back(std::move(object));
      content.names.push_back(entry);
    } catch (const std::exception& e) {
      throw RenderError(label + ": " + e.what());
    }
  }

  if (options.receiver && !real_mesh.positions.empty() && !content.objects.empty()) {
    // The real proxy baked without and with the virtual objects (in the anchor frame) as occluders.
    std::vector<prt::Occluder> virtual_occluders;
    for (const VirtualObject& o : content.objects) {
      if (o.anchor == options.anchor)
        virtual_occluders.push_back({o.mesh.mesh, o.object_to_anchor});
    }
    prt::BakeOptions bake = options.bake;
    bake.interreflection = false;
    bake.bands = std::min(bake.bands, 4);
    const prt::TransferMesh real = prt::Bake(real_mesh, {}, bake);
    const prt::TransferMesh with = prt::Bake(real_mesh, virtual_occluders, bake);
    ShadowReceiver receiver;
    receiver.mesh = real.mesh;
    receiver.bands = real.bands;
    receiver.transfer_real = real.transfer;
    receiver.transfer_with_virtual = with.transfer;
    receiver.anchor = options.anchor;
    content.receiver = std::move(receiver);
  }
  return content;
}

}  // namespace probeless::render
