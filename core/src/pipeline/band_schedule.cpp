#include "pipeline/band_schedule.h"

#include <algorithm>
#include <numeric>

#include "affinity/error.h"

namespace affinity {

std::vector<BandStep> bandSchedule(int height, int bandRows, const std::vector<int>& radii) {
    if (bandRows < 1) throw Error("band schedule: a band needs at least one row");
    std::vector<BandStep> steps;
    std::vector<int> done(radii.size(), 0);
    for (int begin = 0; begin < height; begin += bandRows) {
        BandStep step;
        step.begin = begin;
        step.end = std::min(height, begin + bandRows);
        int available = step.end;  // rows of the current stage's input made so far
        for (std::size_t i = 0; i < radii.size(); ++i) {
            const int end = available == height ? height : std::max(done[i], available - radii[i]);
            step.stages.emplace_back(done[i], end);
            done[i] = end;
            available = end;
        }
        steps.push_back(std::move(step));
    }
    return steps;
}

int bandRingRows(int height, int bandRows, const std::vector<int>& radii) {
    const int reach = std::accumulate(radii.begin(), radii.end(), 0);
    return std::max(1, std::min(height, bandRows + 2 * reach + 2));
}

}  // namespace affinity
