#include "outputs.h"

#include <algorithm>
#include <cstring>
#include <vector>

#include "probeless/sh/sh.h"

namespace probeless::renderer_node {

light::DominantLight DominantOf(const msgs::ShLight& m) {
  light::DominantLight d;
  const float* md = m.dominant_direction;
  if (m.intensity > 0 && md[0] * md[0] + md[1] * md[1] + md[2] * md[2] > 0.5f) {
    d.direction = {md[0], md[1], md[2]};
    d.intensity = m.intensity;
    return d;
  }
  if (m.bands < 2) return d;
  std::vector<double> grey(m.bands * m.bands);
  for (size_t k = 0; k < grey.size(); ++k) {
    grey[k] = (m.coefficients[k][0] + m.coefficients[k][1] + m.coefficients[k][2]) / 3.0;
  }
  const sh::Vec3 dir = sh::OptimalLinearDirection(grey.data());
  if (dir[0] == 0 && dir[1] == 0 && dir[2] == 0) return d;
  d.direction = {static_cast<float>(dir[0]), static_cast<float>(dir[1]),
                 static_cast<float>(dir[2])};
  d.intensity = static_cast<float>(std::max(0.0, sh::DirectionalPower(grey, dir)));
  return d;
}

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
