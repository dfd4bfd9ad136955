#pragma once
// Input fallback (docs/MODEL.md section 10, "Input fallback"). The kernels' output is a weighted average of a
// pixel's neighbours, biased wherever they are not alike in truth: a shadow whose few samples
// hold none of the rare bright ones of the light around it gets that light, detail a frame of
// many samples shows is smoothed. The noisy input is unbiased, and its samples tell its noise.
// Over a small window, D is the mean squared difference between the output's and the input's
// luminance, and V the input's noise: the variance of the window's samples about their mean, over
// the samples per pixel (the variance of a pixel's mean, were the window's samples alike). Where D
// is more than the noise explains, the rest is the output's bias, and the output moves toward the
// input by the share of D that kFallbackNoiseFactor * V does not explain, max(0, D - k V) / D
// (positive-part James-Stein shrinkage). The spread about the window's mean, not within each
// pixel, counts as noise: at 2 samples a pixel whose both samples took the same bright path would
// read as noiseless. V is accumulated along the motion: a window whose samples hold none of a
// region's rare bright ones this frame keeps the noise its earlier frames showed; a frame without
// history (the first, or the first after a cut) only measures it.
#include "kernels/feature_map.h"
#include "pipeline/feature_map_pool.h"

namespace affinity {

// The window: a square holding about this many samples (7 x 7 pixels at 4 samples per pixel,
// 9 x 9 at 2, 5 x 5 at 8), one box pass per axis: its noise is measured from as many samples
// whatever the samples per pixel.
inline constexpr int kFallbackWindowSamples = 196;
// The box radius of that window at `spp` samples per pixel (at least 1).
int fallbackRadius(int spp);
// How many times the input's noise a departure must exceed before any of it counts as bias: the
// variance of heavy-tailed light estimated from a few samples is most often far below its truth.
inline constexpr float kFallbackNoiseFactor = 8.0f;
// The weight of the warped accumulated noise against the frame's own.
inline constexpr float kFallbackHistoryWeight = 0.7f;

// Moves `radiance` (the output, height x width x 3, in place) toward `noisy` (the frame's noisy
// radiance, height x width x 3) as above. meanSquares: the mean squared luminance of each pixel's
// `spp` samples (height x width x 1, filter_signal.h). With `useHistory` (and a history of this
// size) the accumulated noise in `noiseHistory` is warped by `motion` and blended where `valid`;
// without, `radiance` stays as it is. Leaves this frame's accumulated noise in `noiseHistory`. Its
// maps come from `pool`.
void fallBackToInput(const FeatureMap& noisy, const FeatureMap& meanSquares, int spp, const float* motion,
                     const float* valid, bool useHistory, FeatureMap& noiseHistory, float* radiance,
                     FeatureMapPool& pool);

}  // namespace affinity
