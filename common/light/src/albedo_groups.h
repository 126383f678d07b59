// Private to probeless_light: the albedo groups of the per-group albedo fits (EstimateLight,
// EstimatePointLight).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace probeless::light::internal {

// Group ids for rows of linear RGB (3 values per row) and the number of ids (all ids < *count).
// invariant = false: the (r, g) = (R, G) / (R + G + B) chromaticity cell of a cells x cells grid
// (under white light a material's chromaticity is its albedo's). invariant = true: the
// illuminant-invariant 1D coordinate of Finlayson, Drew & Lu 2004 ("Intrinsic images by entropy
// minimization", ECCV): in log chromaticity (log R/G, log B/G) a change of the light's colour
// (e.g. a warm lamp's share against a bluish ambient, varying with the shading) moves every
// material by the same vector, so the projection orthogonal to it — the direction of minimum
// entropy of the projected values (Scott's-rule bins over the middle 90 %) — depends on the
// albedo only; bins of 3 / cells log units. Rows with a non-positive channel sum get id 0.
std::vector<int> AlbedoGroupIds(std::span<const float> rgb, int cells, bool invariant, int* count);

}  // namespace probeless::light::internal
