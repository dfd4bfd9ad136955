// The band schedule of the stages after the U-Net: simulated with rings of bandRingRows() rows,
// every row a stage reads must still be in its ring (not yet overwritten, already written), and
// every stage must output every row exactly once.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "affinity/error.h"
#include "pipeline/band_schedule.h"

namespace affinity {
namespace {

// A ring of `rows` slots remembering which image row each slot holds.
struct RingRecord {
    std::vector<int> slot;
    explicit RingRecord(int rows) : slot(std::size_t(rows), -1) {}
    void write(int begin, int end) {
        for (int y = begin; y < end; ++y) slot[std::size_t(y) % slot.size()] = y;
    }
    // True when every row of [begin, end) clipped to the image is held.
    bool holds(int begin, int end, int height) const {
        for (int y = std::max(0, begin); y < std::min(height, end); ++y)
            if (slot[std::size_t(y) % slot.size()] != y) return false;
        return true;
    }
};

void simulate(int height, int bandRows, const std::vector<int>& radii) {
    const std::string where = "height " + std::to_string(height) + ", band " + std::to_string(bandRows) + ", stages " +
                              std::to_string(radii.size());
    const int ringRows = bandRingRows(height, bandRows, radii);
    ASSERT_LE(ringRows, height) << where;
    RingRecord parameters(ringRows), warped(ringRows);
    std::vector<RingRecord> outputs(radii.size(), RingRecord(ringRows));
    std::vector<int> next(radii.size(), 0);  // the next row each stage must output
    int warpedEnd = 0;
    int parametersEnd = 0;
    for (const BandStep& step : bandSchedule(height, bandRows, radii)) {
        ASSERT_EQ(step.begin, parametersEnd) << where;
        ASSERT_GT(step.end, step.begin) << where;
        parameters.write(step.begin, step.end);
        parametersEnd = step.end;
        ASSERT_EQ(step.stages.size(), radii.size()) << where;
        for (std::size_t i = 0; i < radii.size(); ++i) {
            const auto [begin, end] = step.stages[i];
            ASSERT_EQ(begin, next[i]) << where << ", stage " << i;
            ASSERT_GE(end, begin) << where << ", stage " << i;
            if (begin == end) continue;
            const int r = radii[i];
            const RingRecord& input = i == 0 ? parameters : outputs[i - 1];
            EXPECT_TRUE(parameters.holds(begin - r, end + r, height)) << where << ", stage " << i << " rows " << begin;
            EXPECT_TRUE(input.holds(begin - r, end + r, height)) << where << ", stage " << i << " rows " << begin;
            if (i + 1 == radii.size()) {  // the temporal taps of the last stage: one row each way
                warped.write(warpedEnd, std::min(height, end + 1));
                warpedEnd = std::min(height, end + 1);
                EXPECT_TRUE(warped.holds(begin - 1, end + 1, height)) << where << " rows " << begin;
            }
            outputs[i].write(begin, end);
            next[i] = end;
        }
    }
    EXPECT_EQ(parametersEnd, height) << where;
    for (std::size_t i = 0; i < radii.size(); ++i) EXPECT_EQ(next[i], height) << where << ", stage " << i;
}

TEST(BandSchedule, EveryRowReadIsStillInItsRing) {
    const std::vector<std::vector<int>> stageRadii = {{2, 4, 8}, {8}, {0}, {1, 2, 4, 8, 16}, {7, 7}, {}};
    for (int height : {1, 2, 7, 31, 64, 65, 200, 1080})
        for (int bandRows : {1, 3, 16, 64, 2000})
            for (const std::vector<int>& radii : stageRadii) simulate(height, bandRows, radii);
}

TEST(BandSchedule, RingsAreMuchShorterThanA1080pImage) {
    // Dilations 1, 2, 4 of a 5x5 grid, 64-row bands: 94 rows, under a tenth of the image.
    EXPECT_EQ(bandRingRows(1080, 64, {2, 4, 8}), 94);
    EXPECT_EQ(bandRingRows(50, 64, {2, 4, 8}), 50);
}

TEST(BandSchedule, RejectsAnEmptyBand) { EXPECT_THROW(bandSchedule(10, 0, {2}), Error); }

}  // namespace
}  // namespace affinity
