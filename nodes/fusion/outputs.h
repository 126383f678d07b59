// fusion's publishers, in the order a frame publishes them: scene/tracking, scene/pose,
// scene/aux (publish_aux; before the G_r, so a subscriber finds the views when the G_r arrives)
// and scene/gbuffer (created with the first G_r, re-created when the depth size changes).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/growing_publisher.h"
#include "probeless/node/node.h"
#include "probeless/recon/msgs_io.h"
#include "probeless/recon/pipeline.h"

namespace probeless::fusion {

class FusionOutputs {
 public:
  // Creates scene/tracking, scene/pose and, with aux_pixels > 0, scene/aux for views of up to
  // aux_pixels^2 pixels. `world_frame`: the poses' parent frame id.
  FusionOutputs(node::Node& node, std::string world_frame, int aux_pixels);

  // scene/tracking: the frame's verdict and the counts so far (recon::FillTrackingStatus).
  void PublishTracking(const msgs::Header& header, const recon::FrameResult& r,
                       const recon::TrackingCounts& counts);
  // scene/pose: camera -> world, child frame = header's frame id.
  void PublishPose(const msgs::Header& header, const recon::Pose& camera_to_world);
  // scene/aux (only when created with aux_pixels > 0): `views` as seen from camera_to_world.
  void PublishAux(const msgs::Header& header, const recon::Pose& camera_to_world,
                  const std::vector<recon::AuxiliaryRaycast>& views);
  // scene/gbuffer: a width x height G_r (the frame's depth size) from the merged depth and
  // normals and the frame's image (nullptr: none).
  void PublishGeometry(const msgs::Header& header, uint32_t w, uint32_t h,
                       const recon::DepthImage& depth, const recon::Vec3Image& normals,
                       const msgs::Image* image, std::span<const std::byte> image_payload);

  bool has_aux() const { return aux_pub_.has_value(); }

 private:
  node::Node& node_;
  std::string world_frame_;
  bus::Publisher tracking_pub_, pose_pub_;
  std::optional<bus::Publisher> aux_pub_;
  node::GrowingPublisher<msgs::GeometryBuffer> gbuffer_pub_;
  uint32_t aux_pixels_ = 0;
};

}  // namespace probeless::fusion
