#pragma once
// Peak guard (docs/MODEL.md section 10, "Peak guard"). The temporal kernel and the accumulated
// signal carry their history forward: a firefly of an earlier frame can stay in the output for
// frames after its pixels' samples fell dark again, a spot of one to a few pixels many times
// brighter than the truth that dominates the frame's relative error. Such a spot stands far above
// the output around it, and far above anything the frame's own input shows there. A glint stands
// above its surroundings too, but this frame's samples show it; light the kernels spread from a
// firefly of this frame is bright where the input is, or beside a pixel that is. So a pixel is
// capped where it exceeds both bounds: its luminance at most the larger of kPeakInputFactor x the
// brightest input pixel of its 3 x 3 neighbourhood and kPeakNeighbourFactor x the brightest
// output pixel on the ring kPeakRing pixels away (the 16 around its 3 x 3 neighbourhood: a spot
// of up to 2 x 2 pixels has none of itself there). RGB is scaled: the hue is kept.
#include "kernels/feature_map.h"
#include "pipeline/feature_map_pool.h"

namespace affinity {

inline constexpr float kPeakInputFactor = 4.0f;
inline constexpr float kPeakNeighbourFactor = 1.5f;
inline constexpr int kPeakRing = 2;

// Caps the pixels of `radiance` (height x width x 3, in place) as above, `noisy` the frame's
// noisy radiance (height x width x 3). Returns how many pixels it capped. Its maps come from
// `pool`.
long guardPeaks(const FeatureMap& noisy, float* radiance, FeatureMapPool& pool);

}  // namespace affinity
