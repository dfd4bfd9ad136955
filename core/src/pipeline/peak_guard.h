#pragma once
// Peak guard (docs/MODEL.md section 10, "Peak guard"). The temporal kernel carries its history
// forward: a firefly of an earlier frame can stay in the output for frames after its pixel's
// samples fell dark again, a lone pixel many times brighter than the truth that dominates the
// frame's relative error. Such a pixel stands far above its neighbours in the output, and far
// above anything the frame's own input shows around it. A glint stands above its neighbours
// too, but this frame's samples show it; light the kernels spread from a firefly of this frame
// is bright where the input is. So a pixel is capped where it exceeds both: its luminance at most
// the larger of kPeakInputFactor x the brightest input pixel of its 3 x 3 neighbourhood and
// kPeakNeighbourFactor x the brightest of its 8 output neighbours (RGB scaled, hue kept).
#include "kernels/feature_map.h"
#include "pipeline/feature_map_pool.h"

namespace affinity {

inline constexpr float kPeakInputFactor = 4.0f;
inline constexpr float kPeakNeighbourFactor = 1.5f;

// Caps the pixels of `radiance` (height x width x 3, in place) as above, `noisy` the frame's
// noisy radiance (height x width x 3). Returns how many pixels it capped. Its maps come from
// `pool`.
long guardPeaks(const FeatureMap& noisy, float* radiance, FeatureMapPool& pool);

}  // namespace affinity
