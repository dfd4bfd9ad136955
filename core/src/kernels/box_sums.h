#pragma once
// Box averages along one axis of a one-channel map, for the stages that compare the output with
// the noisy input over a window (the light restoration, the input fallback): each output pixel
// the mean of the inputs within `radius` along the axis that lie inside the image (no padding).
#include "kernels/feature_map.h"

namespace affinity {

// `result` (the same size as `map`, not `map` itself) gets map's rows boxed.
void boxRows(const FeatureMap& map, int radius, FeatureMap& result);
// The same along the columns.
void boxColumns(const FeatureMap& map, int radius, FeatureMap& result);

}  // namespace affinity
