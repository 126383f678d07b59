#include "probeless/capture/registration.h"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace probeless::capture {

void RegisterDepthToColour(const uint16_t* depth, uint32_t depth_step, const Intrinsics& depth_k,
                           const Intrinsics& colour_k, const DepthToColour& extrinsics,
                           uint16_t* out, uint32_t out_step) {
  const uint32_t ow = colour_k.width;
  const uint32_t oh = colour_k.height;
  for (uint32_t y = 0; y < oh; ++y) {
    std::memset(reinterpret_cast<uint8_t*>(out) + static_cast<size_t>(y) * out_step, 0,
                static_cast<size_t>(ow) * 2);
  }
  const auto& r = extrinsics.rotation;
  const double tx = extrinsics.translation_m[0] * 1000.0;
  const double ty = extrinsics.translation_m[1] * 1000.0;
  const double tz = extrinsics.translation_m[2] * 1000.0;
  // Footprint of one depth pixel in the colour image (pixels), at least 1.
  const int span_x = std::max(1, static_cast<int>(std::ceil(colour_k.fx / depth_k.fx - 1e-9)));
  const int span_y = std::max(1, static_cast<int>(std::ceil(colour_k.fy / depth_k.fy - 1e-9)));
  for (uint32_t v = 0; v < depth_k.height; ++v) {
    const auto* row = reinterpret_cast<const uint16_t*>(reinterpret_cast<const uint8_t*>(depth) +
                                                        static_cast<size_t>(v) * depth_step);
    const double yn = (v - depth_k.cy) / depth_k.fy;
    for (uint32_t u = 0; u < depth_k.width; ++u) {
      const uint16_t z = row[u];
      if (z == 0) continue;
      const double xn = (u - depth_k.cx) / depth_k.fx;
      const double px = xn * z, py = yn * z, pz = z;
      const double cx = r[0] * px + r[1] * py + r[2] * pz + tx;
      const double cy = r[3] * px + r[4] * py + r[5] * pz + ty;
      const double cz = r[6] * px + r[7] * py + r[8] * pz + tz;
      if (!(cz > 0.5)) continue;
      const double fu = colour_k.fx * cx / cz + colour_k.cx;
      const double fv = colour_k.fy * cy / cz + colour_k.cy;
      const int iu = static_cast<int>(std::lround(fu));
      const int iv = static_cast<int>(std::lround(fv));
      const uint16_t zc = static_cast<uint16_t>(std::min(65535.0, std::lround(cz) * 1.0));
      for (int dy = 0; dy < span_y; ++dy) {
        const int ty_ = iv + dy;
        if (ty_ < 0 || ty_ >= static_cast<int>(oh)) continue;
        auto* orow = reinterpret_cast<uint16_t*>(reinterpret_cast<uint8_t*>(out) +
                                                 static_cast<size_t>(ty_) * out_step);
        for (int dx = 0; dx < span_x; ++dx) {
          const int tx_ = iu + dx;
          if (tx_ < 0 || tx_ >= static_cast<int>(ow)) continue;
          uint16_t& target = orow[tx_];
          if (target == 0 || zc < target) target = zc;
        }
      }
    }
  }
}

}  // namespace probeless::capture
