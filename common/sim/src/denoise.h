// Private to probeless_sim: an edge-avoiding a-trous wavelet denoiser for path-traced frames
// (Dammertz et al. 2010, with the variance-guided luminance weight of Schied et al. 2017, SVGF),
// so that few paths per pixel give images with the noise of a camera, not of a path tracer.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "probeless/parallel/thread_pool.h"

namespace probeless::sim::internal {

// Guides of one frame, width x height, row-major: first-hit albedo (linear RGB, 3 per pixel),
// unit normal (3 per pixel, any frame), depth (metres; <= 0 = no surface: left as it is) and a
// mask of pixels to leave untouched (emitters seen directly), 1 = keep.
struct DenoiseGuides {
  int width = 0;
  int height = 0;
  std::span<const float> albedo;  // borrowed: the frame's own images, not copies
  std::span<const float> normal;
  std::span<const float> depth;
  std::vector<uint8_t> keep;
};

// Filters `linear_rgb` (3 per pixel) in place: demodulates by the albedo, runs `iterations`
// a-trous passes (5x5 B3 kernel, steps 1, 2, 4, ...) weighted by normal, relative depth and
// luminance (against the propagated variance), and remodulates. Rows run on `pool` (may be
// null); the result does not depend on the thread count.
void DenoiseAtrous(const DenoiseGuides& guides, std::vector<float>& linear_rgb,
                   parallel::ThreadPool* pool, int iterations = 5);

}  // namespace probeless::sim::internal
