#pragma once
// Box averages along one axis of a one-channel map, for the stages that compare the output with
// the noisy input over a window (the light restoration, the input fallback): each output pixel
// the mean of the inputs within `radius` along the axis that lie inside the image (no padding).
#include "kernels/feature_map.h"

namespace affinity {

// `result` (the same size as `map`; it may be `map` itself) gets map boxed along its rows, then
// along its columns: a (2 radius + 1)^2 box. `scratch` (the same size, neither of the others)
// holds the rows' pass.
void boxRowsAndColumns(const FeatureMap& map, int radius, FeatureMap& scratch, FeatureMap& result);

}  // namespace affinity
