#pragma once
// Light restoration (docs/MODEL.md section 10, "Light restoration"): the affinity kernels are
// normalised averages with learnt weights, and on sparse bright samples (the fireflies of
// indirect light in a dim room) they leave part of the light out, so dim interiors came out
// darker than their references. The noisy input is unbiased: over a wide window its mean is the
// light that belongs there. Each output pixel is scaled by the ratio of the input's to the
// output's luminance, both blurred by a wide Gaussian and accumulated over frames along the
// motion. That ratio is itself noisy where a window holds few samples of heavy-tailed light (a
// small or dim frame, a first frame): its excess over 1 is shrunk by d^2 / (d^2 + se^2), d the
// excess and se the ratio's standard error estimated from the input's local variance, and the
// gain kept within [1 / kLightMaxGain, kLightMaxGain].
#include "kernels/feature_map.h"
#include "pipeline/feature_map_pool.h"

namespace affinity {

// The blur: three box passes of this radius, a Gaussian of about 30 pixels' deviation
// (sqrt(r (r + 1))). Wide enough that a window holds thousands of samples at 2 per pixel.
inline constexpr int kLightBoxRadius = 29;
// The weight of the warped accumulation against the frame's own blurred luminance.
inline constexpr float kLightHistoryWeight = 0.7f;
inline constexpr float kLightMaxGain = 2.0f;

// The accumulated blurred luminances of the noisy input and of the output, and the variance of the
// accumulated input (one channel each), carried from frame to frame.
struct LightHistory {
    FeatureMap input, output, inputVariance;
};

// Scales `radiance` (the filtered output, height x width x 3, in place) by the restoration ratio.
// noisy: the frame's noisy radiance (height x width x 3). With `useHistory` (and a history of this
// size), the accumulations are warped by `motion` and blended where `valid`; else they start
// from this frame. Leaves this frame's accumulations in `history`. Its maps come from `pool`
// (the history's too, and the last frame's go back to it).
void restoreLight(const FeatureMap& noisy, const float* motion, const float* valid, bool useHistory,
                  LightHistory& history, float* radiance, FeatureMapPool& pool);

// The three-box blur above on a one-channel map, in place, each box averaging the pixels inside
// the image (no padding): exposed for its tests.
void blurForLight(FeatureMap& map, FeatureMapPool& pool);

}  // namespace affinity
