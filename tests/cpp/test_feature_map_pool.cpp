// The buffer pool behind the denoiser's memory bound: it must hand back the same memory, pick
// the tightest fit without cutting a much larger map down, and grow rather than pile up buffers.
#include <gtest/gtest.h>

#include "pipeline/feature_map_pool.h"

using namespace affinity;

TEST(FeatureMapPool, ReturnedMemoryIsLentAgain) {
    FeatureMapPool pool;
    FeatureMap a = pool.take(4, 5, 6);
    const float* memory = a.data();
    pool.give(a);
    EXPECT_TRUE(a.empty());
    EXPECT_EQ(a.capacity(), 0u);
    FeatureMap b = pool.take(5, 4, 6);  // same size, other shape
    EXPECT_EQ(b.data(), memory);
    EXPECT_EQ(b.height(), 5);
    EXPECT_EQ(b.width(), 4);
    EXPECT_EQ(pool.freeCapacity(), 0u);
}

TEST(FeatureMapPool, PicksTheTightestFreeMapThatFits) {
    FeatureMapPool pool;
    FeatureMap big = pool.take(10, 10, 8), medium = pool.take(10, 10, 4), small = pool.take(10, 10, 1);
    const float* mediumMemory = medium.data();
    pool.give(big);
    pool.give(medium);
    pool.give(small);
    FeatureMap taken = pool.take(10, 10, 3);
    EXPECT_EQ(taken.data(), mediumMemory);
    EXPECT_EQ(pool.freeCapacity(), 100u * 8 + 100u * 1);
}

TEST(FeatureMapPool, KeepsAMapManyTimesTheRequestForLater) {
    static_assert(FeatureMapPool::kKeepRatio == 6);
    FeatureMapPool pool;
    FeatureMap big = pool.take(10, 10, 13);
    const float* bigMemory = big.data();
    pool.give(big);
    FeatureMap small = pool.take(10, 10, 2);  // 1300 > 6 x 200: a new map
    EXPECT_NE(small.data(), bigMemory);
    EXPECT_EQ(pool.freeCapacity(), 1300u);
    FeatureMap third = pool.take(10, 10, 3);  // 1300 <= 6 x 300: the free map
    EXPECT_EQ(third.data(), bigMemory);
    EXPECT_EQ(pool.freeCapacity(), 0u);
}

TEST(FeatureMapPool, TheKeepRatioCanBeSet) {
    FeatureMapPool pool;
    pool.setKeepRatio(2);
    EXPECT_EQ(pool.keepRatio(), 2u);
    FeatureMap big = pool.take(10, 10, 7);
    const float* bigMemory = big.data();
    pool.give(big);
    FeatureMap small = pool.take(10, 10, 3);  // 700 > 2 x 300: a new map
    EXPECT_NE(small.data(), bigMemory);
    FeatureMap half = pool.take(10, 10, 4);  // 700 <= 2 x 400: the free map
    EXPECT_EQ(half.data(), bigMemory);
}

TEST(FeatureMapPool, GrowsTheLargestFreeMapWhenNoneFits) {
    FeatureMapPool pool;
    FeatureMap a = pool.take(10, 10, 2), b = pool.take(10, 10, 1);
    pool.give(a);
    pool.give(b);
    FeatureMap grown = pool.take(10, 10, 5);
    EXPECT_EQ(grown.capacity(), 500u);
    EXPECT_EQ(pool.freeCapacity(), 100u);  // only the smaller map is left; no third buffer
}

TEST(FeatureMap, MovedFromMapIsEmptyAndReusable) {
    FeatureMap a(3, 3, 2);
    a.fill(1.0f);
    FeatureMap b = std::move(a);
    EXPECT_EQ(a.capacity(), 0u);  // NOLINT(bugprone-use-after-move): the state after a move is the contract
    a.resize(2, 2, 1);
    a.fill(2.0f);
    EXPECT_EQ(a.data()[3], 2.0f);
    EXPECT_EQ(b.data()[17], 1.0f);
}
