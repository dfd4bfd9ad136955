// The feature schema is a contract between producers and consumers: check it is well-formed.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "affinity/error.h"
#include "affinity/features.h"

namespace affinity {
namespace {

TEST(Features, ChannelNamesAreUnique) {
    std::set<std::string> names;
    for (int c = 0; c < kFeatureCount; ++c) names.insert(featureChannelName(c));
    EXPECT_EQ(names.size(), std::size_t(kFeatureCount));
}

TEST(Features, ChannelNamesFollowGroups) {
    EXPECT_EQ(featureChannelName(0), "diffuse.R");
    EXPECT_EQ(featureChannelName(channel::kNormal + 2), "normal.Z");
    EXPECT_EQ(featureChannelName(channel::kDepth), "depth.Z");
    EXPECT_EQ(featureChannelName(channel::kSpecularBounce), "specular_bounce.Y");
    for (const FeatureGroup& group : kFeatureGroups) {
        for (int i = 0; i < group.count; ++i) {
            EXPECT_EQ(featureChannelName(group.offset + i),
                      std::string(group.name) + "." + group.components[std::size_t(i)]);
        }
    }
}

TEST(Features, GroupsTileAllChannelsWithoutGaps) {
    int next = 0;
    for (const FeatureGroup& group : kFeatureGroups) {
        EXPECT_EQ(group.offset, next) << group.name;
        EXPECT_GE(group.count, 1) << group.name;
        EXPECT_EQ(group.components.size(), std::size_t(group.count)) << group.name;
        EXPECT_LE(group.minValue, group.maxValue) << group.name;
        next = group.offset + group.count;
    }
    EXPECT_EQ(next, kFeatureCount);
}

TEST(Features, ChannelIndexConstantsStartTheirGroups) {
    const int expected[] = {channel::kDiffuse,      channel::kSpecular,      channel::kNormal,   channel::kDepth,
                            channel::kAlbedo,       channel::kRoughness,     channel::kEmissive, channel::kMetallic,
                            channel::kTransmissive, channel::kSpecularBounce};
    ASSERT_EQ(std::size(expected), kFeatureGroups.size());
    for (std::size_t g = 0; g < kFeatureGroups.size(); ++g) {
        EXPECT_EQ(kFeatureGroups[g].offset, expected[g]) << kFeatureGroups[g].name;
    }
}

TEST(Features, OutOfRangeChannelThrows) {
    EXPECT_THROW(featureChannelName(-1), Error);
    EXPECT_THROW(featureChannelName(kFeatureCount), Error);
}

TEST(Features, FlagChannelsAreExactlyTheLastFour) {
    for (int c = 0; c < kFeatureCount; ++c) {
        EXPECT_EQ(isFlagChannel(c), c >= 14 && c <= 17) << c;
    }
    EXPECT_TRUE(isFlagChannel(channel::kEmissive));
    EXPECT_TRUE(isFlagChannel(channel::kMetallic));
    EXPECT_TRUE(isFlagChannel(channel::kTransmissive));
    EXPECT_TRUE(isFlagChannel(channel::kSpecularBounce));
}

}  // namespace
}  // namespace affinity
