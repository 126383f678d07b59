#include "outputs.h"

#include <cstring>

namespace probeless::renderer_node {

void CompositePublisher::Publish(const msgs::Header& header, int width, int height,
                                 const render::Composite& composite) {
  bus::Loan loan =
      publisher_.Borrow(msgs::Image::MessageBytesFor(width, height, msgs::Encoding::kRgb8));
  auto view = msgs::WriteMessage<msgs::Image>(loan.data());
  view->header = header;
  view->Init(width, height, msgs::Encoding::kRgb8);
  std::memcpy(view.payload.data(), composite.rgb.data(), composite.rgb.size());
  publisher_.Publish(std::move(loan));
}

}  // namespace probeless::renderer_node
