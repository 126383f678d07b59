// The albedo groups of the estimators (private src/albedo_groups.h): chromaticity cells, and the
// illuminant-invariant coordinate under a light whose colour varies with the shading.
#include "albedo_groups.h"

#include <gtest/gtest.h>

#include <random>
#include <set>
#include <vector>

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

}  // namespace
}  // namespace probeless::light::internal
