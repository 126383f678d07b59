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

// The colour the albedo and shadow groups read (sRGB 8-bit, 3 bytes a pixel, width x height, as
// `colour`). A pixel with a channel >= clip_level was clipped by the camera: its intensity is a
// lower bound and its chromaticity is lost (a sunlit table reads white), so it would form a group
// of its own and the lit and shadowed parts of one material could never be compared. It takes
// the chromaticity of the nearest unclipped pixel on the same surface instead (4-connected
// geodesic distance; neighbours are joined when both depths are > 0 and differ by at most
// max_jump_rel x depth, or when `depth` is empty, and — with `normals` (3 floats a pixel, or
// empty) — when their normals are within max_crease_deg: a table's side is another surface than
// its top), scaled in linear light so that its brightest channel is 255. Clipped pixels that reach
// no unclipped one keep their colour. *filled, if given, receives the number of pixels changed.
std::vector<uint8_t> FillClippedChroma(std::span<const uint8_t> colour,
                                       std::span<const float> depth, std::span<const float> normals,
                                       int width, int height, int clip_level = 254,
                                       float max_jump_rel = 0.03f, float max_crease_deg = 30,
                                       size_t* filled = nullptr);

}  // namespace probeless::light::internal
