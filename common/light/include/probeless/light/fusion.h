// Light fusion: one light from several estimates of the same lighting (beyond both papers): the
// face-based estimate (Knorr & Kurz 2014) and the scene-based one (Gruber et al. 2015) combined by
// their confidences, so the renderer can follow whichever is better at the moment.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>

#include "probeless/msgs/sh_light.h"

namespace probeless::light {

class FusionError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct FusionOptions {
  // An input whose header.stamp_ns is more than this older than the newest input is ignored, ns.
  int64_t max_age_ns = 500'000'000;
  // Inputs with confidence below this are ignored.
  float min_confidence = 0.05f;
};

// Fuses `inputs` (all msgs::ShLight of the same frame_id, e.g. the camera frame):
// - weights w_i = confidence_i of the inputs that are fresh (FusionOptions::max_age_ns) and
//   confident enough;
// - coefficients: sum w_i c_i / sum w_i over the bands both have (the result has the largest band
//   count; coefficients only one input has are taken from it with its weight alone);
// - dominant direction: the normalised w-weighted sum of the unit directions (inputs without one
//   are left out); intensity: the w-weighted mean;
// - confidence: 1 - prod(1 - c_i) (independent estimates reinforce each other);
// - header: the newest input's.
// Returns nullopt when no input qualifies. Throws FusionError when the frames differ (naming them)
// or an input fails ShLight::Validate.
std::optional<msgs::ShLight> FuseLights(std::span<const msgs::ShLight> inputs,
                                        const FusionOptions& options = {});

}  // namespace probeless::light
