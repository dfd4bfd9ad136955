#pragma once
// The order in which the stages after the U-Net make rows when they run band by band down the
// image: kernel parameters for a band of rows, then each affinity kernel as far as its input
// allows (a kernel's output row y needs its input and parameters up to row y + radius). Maps
// between the stages then need only a ring of rows (bandRingRows) instead of the whole image,
// which is what keeps 1080p under the memory target (docs/MODEL.md, "Memory").
#include <utility>
#include <vector>

namespace affinity {

struct BandStep {
    int begin = 0, end = 0;                   // rows of kernel parameters made in this step
    std::vector<std::pair<int, int>> stages;  // rows [first, second) each filter stage outputs
};

// Steps covering `height` rows, `bandRows` rows of parameters per step, for filter stages whose
// taps reach radii[i] rows up and down. Every stage outputs every row exactly once, in order.
std::vector<BandStep> bandSchedule(int height, int bandRows, const std::vector<int>& radii);

// Rows a ring must hold so that no row is overwritten before the last stage that reads it has
// run: the band, each stage's lag behind the parameters, and the reach of the farthest tap.
int bandRingRows(int height, int bandRows, const std::vector<int>& radii);

}  // namespace affinity
