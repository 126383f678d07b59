// The albedo groups of the estimators (private src/albedo_groups.h): chromaticity cells, and the
// illuminant-invariant coordinate under a light whose colour varies with the shading.
#include "albedo_groups.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <set>
#include <vector>

#include "probeless/light/transfer.h"

namespace probeless::light::internal {
namespace {

// Rows of three materials lit by a warm lamp (share s in [0, 1]) over a bluish ambient:
// colour = albedo * (s * lamp + ambient), per channel.
std::vector<float> WarmLampRows(std::vector<int>* material) {
  const float albedo[3][3] = {{0.55f, 0.40f, 0.25f}, {0.20f, 0.35f, 0.60f}, {0.30f, 0.70f, 0.30f}};
  const float lamp[3] = {1.0f, 0.8f, 0.55f}, ambient[3] = {0.10f, 0.11f, 0.14f};
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> share(0.0f, 1.0f);
  std::vector<float> rgb;
  for (int i = 0; i < 600; ++i) {
    const int k = i % 3;
    const float s = share(rng);
    for (int c = 0; c < 3; ++c) rgb.push_back(albedo[k][c] * (s * lamp[c] + ambient[c]));
    material->push_back(k);
  }
  return rgb;
}

TEST(AlbedoGroups, ChromaticityCellsSplitAMaterialUnderAColouredLamp) {
  std::vector<int> material;
  const std::vector<float> rgb = WarmLampRows(&material);
  int count = 0;
  const std::vector<int> id = AlbedoGroupIds(rgb, 32, false, &count);
  EXPECT_EQ(count, 32 * 32);
  std::set<int> first;
  for (size_t i = 0; i < id.size(); ++i) {
    ASSERT_LT(id[i], count);
    if (material[i] == 0) first.insert(id[i]);
  }
  EXPECT_GT(first.size(), 2u) << "the lamp's share moves the chromaticity over several cells";
}

TEST(AlbedoGroups, InvariantCoordinateKeepsMaterialsApartAndWhole) {
  std::vector<int> material;
  const std::vector<float> rgb = WarmLampRows(&material);
  int count = 0;
  const std::vector<int> id = AlbedoGroupIds(rgb, 32, true, &count);
  ASSERT_GE(count, 1);
  std::vector<std::set<int>> ids(3);
  for (size_t i = 0; i < id.size(); ++i) {
    ASSERT_GE(id[i], 0);
    ASSERT_LT(id[i], count);
    ids[material[i]].insert(id[i]);
  }
  for (int k = 0; k < 3; ++k) {
    EXPECT_LE(ids[k].size(), 2u) << "material " << k << " spread over " << ids[k].size() << " bins";
    for (int j = k + 1; j < 3; ++j) {
      for (int v : ids[k]) EXPECT_EQ(ids[j].count(v), 0u) << "materials " << k << ", " << j;
    }
  }
}

TEST(AlbedoGroups, BlackRowsGetGroupZero) {
  const std::vector<float> rgb = {0, 0, 0, 0.5f, 0.4f, 0.3f};
  int count = 0;
  const std::vector<int> id = AlbedoGroupIds(rgb, 16, false, &count);
  EXPECT_EQ(id[0], 0);
  EXPECT_EQ(count, 256);
}

// A yellowish table (left half, depth 2 m) whose sunlit middle is clipped to white, beside a blue
// wall (right half, depth 4 m) with a clipped patch of its own: each clipped pixel takes its own
// surface's chromaticity at full brightness, never the other surface's.
TEST(AlbedoGroups, ClippedPixelsTakeTheChromaticityOfTheirSurface) {
  const int w = 40, h = 10;
  std::vector<uint8_t> rgb(3 * w * h);
  std::vector<float> depth(w * h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const int i = y * w + x;
      const bool table = x < 20;
      const bool clipped = table ? (x >= 6 && x < 14) : (x >= 30 && x < 34);
      const uint8_t shadowed[2][3] = {{120, 100, 60}, {40, 60, 110}};
      const uint8_t* c = shadowed[table ? 0 : 1];
      for (int k = 0; k < 3; ++k) rgb[3 * i + k] = clipped ? 255 : c[k];
      depth[i] = table ? 2.0f : 4.0f;
    }
  }
  size_t filled = 0;
  const std::vector<uint8_t> out = FillClippedChroma(rgb, depth, {}, w, h, 254, 0.03f, 30, &filled);
  EXPECT_EQ(filled, static_cast<size_t>(8 * h + 4 * h));
  auto chroma = [](const uint8_t* c, int k) {
    const float r = SrgbToLinear(c[0]), g = SrgbToLinear(c[1]), b = SrgbToLinear(c[2]);
    return (k == 0 ? r : g) / (r + g + b);
  };
  for (int y = 0; y < h; ++y) {
    for (int x : {6, 10, 13, 30, 33}) {
      const uint8_t* got = &out[3 * (y * w + x)];
      const uint8_t* want = &rgb[3 * (y * w + (x < 20 ? 2 : 25))];  // the surface, unclipped
      EXPECT_EQ(std::max({got[0], got[1], got[2]}), 255) << x << ", " << y;
      EXPECT_NEAR(chroma(got, 0), chroma(want, 0), 0.01f) << x << ", " << y;
      EXPECT_NEAR(chroma(got, 1), chroma(want, 1), 0.01f) << x << ", " << y;
    }
  }
  // Unclipped pixels are untouched; a fully clipped image has no source and stays as it was.
  EXPECT_EQ(out[0], 120);
  EXPECT_EQ(out[3 * 25 + 2], 110);
  const std::vector<uint8_t> white(3 * w * h, 255);
  EXPECT_EQ(FillClippedChroma(white, depth, {}, w, h, 254, 0.03f, 30, &filled), white);
  EXPECT_EQ(filled, 0u);
}

// A table top clipped everywhere beside its side (same depth at the edge, normal 90 deg away): the
// side is another surface, so the top keeps its colour; without normals it would take the side's.
TEST(AlbedoGroups, ClippedChromaDoesNotCrossACrease) {
  const int w = 20, h = 10;
  std::vector<uint8_t> rgb(3 * w * h);
  std::vector<float> depth(w * h, 2.0f), normals(3 * w * h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const int i = y * w + x;
      const bool top = y < 6;
      for (int k = 0; k < 3; ++k) rgb[3 * i + k] = top ? 255 : (k == 2 ? 40 : 80);
      normals[3 * i + (top ? 1 : 2)] = -1;  // up (-y) for the top, towards the camera for the side
    }
  }
  size_t filled = 1;
  EXPECT_EQ(FillClippedChroma(rgb, depth, normals, w, h, 254, 0.03f, 30, &filled), rgb);
  EXPECT_EQ(filled, 0u);
  const std::vector<uint8_t> crossed =
      FillClippedChroma(rgb, depth, {}, w, h, 254, 0.03f, 30, &filled);
  EXPECT_EQ(filled, static_cast<size_t>(6 * w));
  // (80, 80, 40)'s chromaticity at full brightness: linear (1, 1, 0.26), sRGB (255, 255, 141).
  EXPECT_EQ(crossed[0], 255);
  EXPECT_NEAR(crossed[2], 141, 1);
}

}  // namespace
}  // namespace probeless::light::internal
