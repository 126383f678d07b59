// Unit tests of probeless/node/stamp_cache.h: pairing topics by header stamp (issue #21).
#include "probeless/node/stamp_cache.h"

#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "probeless/msgs/layout.h"
#include "probeless/node/node.h"

namespace probeless::node {
namespace {

constexpr int64_t kMs = 1'000'000;  // ns

// A cache of strings added under the given stamps, each value "s<stamp>".
StampCache<std::string> Filled(size_t capacity, const std::vector<int64_t>& stamps) {
  StampCache<std::string> cache(capacity);
  for (int64_t s : stamps) cache.Add(s, std::string("s").append(std::to_string(s)));
  return cache;
}

TEST(StampCache, ExactFindsOnlyTheSameStamp) {
  const auto cache = Filled(8, {10 * kMs, 20 * kMs, 30 * kMs});
  ASSERT_NE(cache.Exact(20 * kMs), nullptr);
  EXPECT_EQ(*cache.Exact(20 * kMs), "s20000000");
  EXPECT_EQ(cache.Exact(20 * kMs + 1), nullptr);
  EXPECT_EQ(cache.Exact(5 * kMs), nullptr);
  EXPECT_EQ(cache.Exact(40 * kMs), nullptr);
}

TEST(StampCache, LatestAtOrBeforeTakesTheNewestNotAfterTheStamp) {
  const auto cache = Filled(8, {10, 20, 30});
  EXPECT_EQ(*cache.LatestAtOrBefore(30), "s30");  // the same stamp counts
  EXPECT_EQ(*cache.LatestAtOrBefore(29), "s20");
  EXPECT_EQ(*cache.LatestAtOrBefore(1000), "s30");  // no age limit by default
  EXPECT_EQ(cache.LatestAtOrBefore(9), nullptr);    // all are later
}

TEST(StampCache, LatestAtOrBeforeHonoursTheTolerance) {
  const auto cache = Filled(8, {10, 20, 30});
  EXPECT_EQ(*cache.LatestAtOrBefore(35, 5), "s30");   // exactly the tolerance away: taken
  EXPECT_EQ(cache.LatestAtOrBefore(36, 5), nullptr);  // the newest candidate is too old
  EXPECT_EQ(*cache.LatestAtOrBefore(30, 0), "s30");   // tolerance 0 = exact
  EXPECT_EQ(cache.LatestAtOrBefore(31, 0), nullptr);
  EXPECT_EQ(cache.LatestAtOrBefore(30, -1), nullptr);  // a negative tolerance matches nothing
}

TEST(StampCache, ToleranceDoesNotOverflowForExtremeStamps) {
  StampCache<int> cache(4);
  cache.Add(INT64_MIN, 1);
  EXPECT_EQ(cache.LatestAtOrBefore(INT64_MAX, 5), nullptr);
  ASSERT_NE(cache.LatestAtOrBefore(INT64_MAX), nullptr);  // kAnyAge: any age
  EXPECT_EQ(*cache.LatestAtOrBefore(INT64_MAX), 1);
}

TEST(StampCache, DuplicateStampsExactTakesTheFirstLatestTheLast) {
  StampCache<std::string> cache(8);
  cache.Add(10, "a");
  EXPECT_FALSE(cache.Add(20, "first"));
  EXPECT_FALSE(cache.Add(20, "second"));  // a tie is not a reset
  EXPECT_EQ(cache.size(), 3u);
  EXPECT_EQ(*cache.Exact(20), "first");
  EXPECT_EQ(*cache.LatestAtOrBefore(25), "second");
  EXPECT_EQ(cache.resets(), 0u);
}

TEST(StampCache, FullCacheEvictsTheOldest) {
  auto cache = Filled(3, {1, 2, 3, 4});
  EXPECT_EQ(cache.size(), 3u);
  EXPECT_EQ(cache.capacity(), 3u);
  EXPECT_EQ(cache.Exact(1), nullptr);
  EXPECT_EQ(*cache.Exact(2), "s2");
  EXPECT_EQ(*cache.Exact(4), "s4");
  EXPECT_EQ(cache.LatestAtOrBefore(1), nullptr);  // evicted, not found as "before"
  cache.Add(4, "dup");                            // duplicates count against the capacity too
  EXPECT_EQ(cache.Exact(2), nullptr);
  EXPECT_EQ(cache.size(), 3u);
}

TEST(StampCache, BackwardsStampClearsTheCache) {
  StampCache<std::string> cache(8);
  cache.Add(100, "old1");
  cache.Add(200, "old2");
  EXPECT_TRUE(cache.Add(50, "new1"));  // a restarted source
  EXPECT_EQ(cache.resets(), 1u);
  EXPECT_EQ(cache.size(), 1u);
  EXPECT_EQ(cache.Exact(100), nullptr);
  EXPECT_EQ(cache.Exact(200), nullptr);
  EXPECT_EQ(*cache.LatestAtOrBefore(300), "new1");  // nothing of the old stream is left
  EXPECT_EQ(cache.newest_stamp(), 50);
}

TEST(StampCache, DropUpToRemovesTheStampAndOlder) {
  auto cache = Filled(8, {10, 20, 20, 30});
  EXPECT_EQ(cache.DropUpTo(20), 3u);
  EXPECT_EQ(cache.size(), 1u);
  EXPECT_EQ(cache.Exact(20), nullptr);
  EXPECT_EQ(*cache.Exact(30), "s30");
  EXPECT_EQ(cache.DropUpTo(5), 0u);
  EXPECT_EQ(cache.DropUpTo(30), 1u);
  EXPECT_TRUE(cache.empty());
  EXPECT_EQ(cache.newest_stamp(), std::nullopt);
  // Empty again: any stamp is accepted without a reset.
  EXPECT_FALSE(cache.Add(1, "x"));
  EXPECT_EQ(cache.resets(), 0u);
}

TEST(StampCache, ClearIsNotAReset) {
  auto cache = Filled(8, {10, 20});
  cache.Clear();
  EXPECT_TRUE(cache.empty());
  EXPECT_EQ(cache.resets(), 0u);
  EXPECT_EQ(cache.Exact(10), nullptr);
}

TEST(StampCache, HoldsMoveOnlyValuesAndLookupsAreMutable) {
  StampCache<std::unique_ptr<int>> cache(2);
  cache.Add(1, std::make_unique<int>(7));
  ASSERT_NE(cache.Exact(1), nullptr);
  **cache.Exact(1) = 8;
  EXPECT_EQ(**cache.LatestAtOrBefore(1), 8);
}

TEST(StampCache, ZeroCapacityIsRejected) { EXPECT_THROW(StampCache<int>(0), NodeError); }

TEST(HeldMessage, CopiesAlignedAndSurvivesMoves) {
  std::vector<std::byte> bytes(100);
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<std::byte>(i);
  // From an unaligned source.
  HeldMessage held(std::span<const std::byte>(bytes).subspan(1));
  ASSERT_EQ(held.bytes().size(), 99u);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(held.bytes().data()) % msgs::kPayloadAlignment, 0u);
  EXPECT_EQ(held.bytes()[0], std::byte{1});
  EXPECT_EQ(held.bytes()[98], std::byte{99});
  StampCache<HeldMessage> cache(1);
  cache.Add(5, std::move(held));
  EXPECT_TRUE(held.bytes().empty());  // moved from: empty
  const HeldMessage* in = cache.Exact(5);
  ASSERT_NE(in, nullptr);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(in->bytes().data()) % msgs::kPayloadAlignment, 0u);
  EXPECT_EQ(in->bytes()[50], std::byte{51});
  EXPECT_TRUE(HeldMessage().bytes().empty());
}

}  // namespace
}  // namespace probeless::node
