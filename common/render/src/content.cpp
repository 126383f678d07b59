#include "probeless/render/content.h"

#include <algorithm>
#include <cctype>

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

}  // namespace

Content LoadContent(const ContentOptions& options) {
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
        object.mesh = prt::Bake(prt::MakeDemoObject(entry), occluders, options.bake);
      } else if (Extension(entry) == "prt") {
        object.mesh = prt::LoadPrt(entry);
      } else if (Extension(entry) == "obj" || Extension(entry) == "ply") {
        object.mesh = prt::Bake(raytrace::LoadMesh(entry), occluders, options.bake);
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
