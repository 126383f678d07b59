// Hard-coded real SH basis (bands 1..4) for the bake's inner loop; the convention of
// probeless/sh/sh.h (Condon-Shortley phase, index l(l+1)+m), checked against sh::EvaluateBasis by
// prt_test. Bands 5 fall back to sh::EvaluateBasis.
#pragma once

#include "probeless/sh/sh.h"

namespace probeless::prt::internal {

// Y_0..Y_{bands^2-1} at unit direction (x, y, z).
inline void FastBasis(int bands, float x, float y, float z, float* out) {
  if (bands > 4) {
    sh::EvaluateBasis<float>(bands, x, y, z, out);
    return;
  }
  out[0] = 0.28209479177387814f;
  if (bands < 2) return;
  out[1] = -0.4886025119029199f * y;
  out[2] = 0.4886025119029199f * z;
  out[3] = -0.4886025119029199f * x;
  if (bands < 3) return;
  out[4] = 1.0925484305920792f * x * y;
  out[5] = -1.0925484305920792f * y * z;
  out[6] = 0.31539156525252005f * (3 * z * z - 1);
  out[7] = -1.0925484305920792f * x * z;
  out[8] = 0.5462742152960396f * (x * x - y * y);
  if (bands < 4) return;
  out[9] = -0.5900435899266435f * y * (3 * x * x - y * y);
  out[10] = 2.890611442640554f * x * y * z;
  out[11] = -0.4570457994644658f * y * (5 * z * z - 1);
  out[12] = 0.3731763325901154f * z * (5 * z * z - 3);
  out[13] = -0.4570457994644658f * x * (5 * z * z - 1);
  out[14] = 1.445305721320277f * z * (x * x - y * y);
  out[15] = -0.5900435899266435f * x * (x * x - 3 * y * y);
}

}  // namespace probeless::prt::internal
