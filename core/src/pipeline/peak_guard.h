#pragma once
// Peak guard (docs/MODEL.md section 10, "Peak guard"). The temporal kernel and the accumulated
// signal carry their history forward: a firefly of an earlier frame can stay in the output for
// frames after its pixels' samples fell dark again, a spot of one to a few pixels many times
// brighter than the truth that dominates the frame's relative error; and the kernels keep much of
// a firefly of this frame where it landed. Such a spot stands far above the output around it, and
// far above the light this frame's input shows there in more than one sample. A glint stands
// above its surroundings too, but this frame's samples show it; a sub-pixel lamp may be seen by
// one sample only, but that sample saw an emitter. So a pixel is capped where it exceeds both
// bounds: its luminance at most the larger of kPeakInputFactor x the input's support in its 3 x 3
// neighbourhood and kPeakNeighbourFactor x the brightest output pixel on the ring kPeakRing
// pixels away (the 16 around its 3 x 3 neighbourhood: a spot of up to 2 x 2 pixels has none of
// itself there). A pixel's support is its input luminance where a sample saw an emitter, else
// that luminance less the most one sample can hold of it, sqrt(mean square / spp), the light at
// least two samples show. RGB is scaled: the hue is kept. It runs on the kernels' output, before
// the light restoration, which gives the light taken back at its 30-pixel scale (where the
// model's file turns it on): a firefly's light belongs to a region, not to a pixel or its halo.
#include "kernels/feature_map.h"
#include "pipeline/feature_map_pool.h"

namespace affinity {

inline constexpr float kPeakInputFactor = 8.0f;
inline constexpr float kPeakNeighbourFactor = 1.5f;
inline constexpr int kPeakRing = 2;

// The input's support of a pixel of mean luminance `luminance`, mean squared sample luminance
// `meanSquare` over `spp` samples, `emissiveShare` of which saw an emitter.
float peakSupport(float luminance, float meanSquare, float emissiveShare, int spp);

// Caps the pixels of `radiance` (height x width x 3, in place) as above. noisy: the frame's noisy
// radiance (height x width x 3); meanSquares and emissiveShare: its samples' mean squared
// luminance and share that saw an emitter (height x width x 1 each, filter_signal.h), over `spp`
// samples. Returns how many pixels it capped. Its maps come from `pool`.
long guardPeaks(const FeatureMap& noisy, const FeatureMap& meanSquares, const FeatureMap& emissiveShare, int spp,
                float* radiance, FeatureMapPool& pool);

}  // namespace affinity
