#include "outputs.h"

#include <utility>

namespace probeless::fusion {

FusionOutputs::FusionOutputs(node::Node& node, std::string world_frame, int aux_pixels)
    : node_(node),
      world_frame_(std::move(world_frame)),
      tracking_pub_(node.CreatePublisher<msgs::TrackingStatus>("scene/tracking")),
      pose_pub_(node.CreatePublisher<msgs::Pose>("scene/pose")),
      gbuffer_pub_(node, "scene/gbuffer") {
  if (aux_pixels > 0) {
    aux_pixels_ = static_cast<uint32_t>(aux_pixels);
    bus::PublisherOptions po;
    po.max_message_bytes = msgs::AuxiliaryViews::MessageBytesFor(4, aux_pixels_, aux_pixels_);
    aux_pub_.emplace(node.CreatePublisher<msgs::AuxiliaryViews>("scene/aux", po));
  }
}

void FusionOutputs::PublishTracking(const msgs::Header& header, const recon::FrameResult& r,
                                    const recon::TrackingCounts& counts) {
  bus::Loan loan = tracking_pub_.Borrow(sizeof(msgs::TrackingStatus));
  auto t = msgs::WriteMessage<msgs::TrackingStatus>(loan.data());
  t->header = header;
  recon::FillTrackingStatus(r, counts, t.message);
  tracking_pub_.Publish(std::move(loan));
}

void FusionOutputs::PublishPose(const msgs::Header& header, const recon::Pose& camera_to_world) {
  bus::Loan loan = pose_pub_.Borrow(sizeof(msgs::Pose));
  auto out = msgs::WriteMessage<msgs::Pose>(loan.data());
  out->header = header;
  out->SetParentFrameId(world_frame_);
  out->SetChildFrameId(header.FrameId());
  out->transform = camera_to_world.ToMsg();
  pose_pub_.Publish(std::move(loan));
}

void FusionOutputs::PublishAux(const msgs::Header& header, const recon::Pose& camera_to_world,
                               const std::vector<recon::AuxiliaryRaycast>& views) {
  const uint32_t n = aux_pixels_;
  bus::Loan loan = aux_pub_->Borrow(
      msgs::AuxiliaryViews::MessageBytesFor(static_cast<uint32_t>(views.size()), n, n));
  auto aux = msgs::WriteMessage<msgs::AuxiliaryViews>(loan.data());
  aux->header = header;
  recon::WriteAuxiliaryViews(camera_to_world, views, *aux, aux.payload);
  aux_pub_->Publish(std::move(loan));
}

void FusionOutputs::PublishGeometry(const msgs::Header& header, uint32_t w, uint32_t h,
                                    const recon::DepthImage& depth, const recon::Vec3Image& normals,
                                    const msgs::Image* image,
                                    std::span<const std::byte> image_payload) {
  bus::Loan loan = gbuffer_pub_.Borrow(msgs::GeometryBuffer::MessageBytesFor(w, h));
  auto out = msgs::WriteMessage<msgs::GeometryBuffer>(loan.data());
  out->header = header;
  recon::WriteGeometryBuffer(depth, normals, image, image_payload, *out, out.payload);
  gbuffer_pub_.Publish(std::move(loan));
}

}  // namespace probeless::fusion
