#include "outputs.h"

#include <algorithm>

#include "probeless/light/messages.h"

namespace probeless::scene_light {

SceneOutputs::SceneOutputs(node::Node& node, bool publish_transfer)
    : publish_transfer_(publish_transfer),
      light_pub_(node.CreatePublisher<msgs::ShLight>("scene/light")),
      transfer_pub_(node, "scene/transfer"),
      indirect_pub_(node, "scene/indirect") {}

bool SceneOutputs::Publish(const msgs::Header& header, const light::ScenePipelineResult& r) {
  const light::LightEstimate& e = r.light;
  if (e.valid) {
    bus::Loan loan = light_pub_.Borrow(sizeof(msgs::ShLight));
    auto out = msgs::WriteMessage<msgs::ShLight>(loan.data());
    out->header = header;
    light::FillShLight(e, out.message);
    for (auto& coefficient : out.message->coefficients) {  // white -> the illuminant's colour
      for (int c = 0; c < 3; ++c) coefficient[c] *= r.colour[c];
    }
    light_pub_.Publish(std::move(loan));
  }
  const light::TransferResult& result = *r.transfer;
  if (publish_transfer_) {
    const uint32_t w = result.width, h = result.height, cc = result.coefficient_count;
    const size_t bytes = msgs::TransferBuffer::MessageBytesFor(w, h, cc);
    bus::Loan loan = transfer_pub_.Borrow(bytes);
    auto out = msgs::WriteMessage<msgs::TransferBuffer>(loan.data());
    out->header = header;
    out->Init(w, h, cc);
    const auto dst = msgs::TransferCoefficients(*out.message, out.payload);
    std::copy(result.transfer.begin(), result.transfer.end(), dst.begin());
    transfer_pub_.Publish(std::move(loan));
  }
  if (r.has_indirect) {
    const size_t bytes =
        msgs::Image::MessageBytesFor(result.width, result.height, msgs::Encoding::kRgb32f);
    bus::Loan loan = indirect_pub_.Borrow(bytes);
    auto out = msgs::WriteMessage<msgs::Image>(loan.data());
    out->header = header;
    light::FillIndirectImage(result, out.message, out.payload);
    indirect_pub_.Publish(std::move(loan));
  }
  return e.valid;
}

}  // namespace probeless::scene_light
