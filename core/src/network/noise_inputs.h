#pragma once
// The U-Net's two noise inputs (docs/MODEL.md section 4, config.noise_inputs_spp): what the mean
// embedding cannot say, how noisy the pixel's mean is. Channel 0: the frame's sample count,
// log2(min(spp, saturation)) / 3, the same everywhere (a count above the saturation, the most the
// training data held, reads as the saturation); channel 1: log1p of the relative variance of the
// pixel's mean luminance, var(luminance) / (spp (mean² + floor²)), from the samples' sums, with the
// radiance exposed as the embedding sees it (0 at one sample per pixel, where it is unknown).
#include "kernels/feature_map.h"

namespace affinity {

inline constexpr int kNoiseInputChannels = 2;
// Scale of the count channel: 8 samples (the shipped training data's) read as 1.
inline constexpr float kNoiseCountScale = 1.0f / 3.0f;
// Exposed luminance below which a pixel's noise counts as relative to this floor instead (dark
// pixels would otherwise read as the noisiest).
inline constexpr float kNoiseLuminanceFloor = 0.01f;

// signal: the mean radiance (height x width x 3, linear, unexposed); meanSquares: the mean over the
// samples of their squared luminance (height x width x 1, unexposed); exposure: the factor the
// embedding's radiance was scaled by. noise: resized to height x width x kNoiseInputChannels.
// Multithreaded; the values do not depend on the thread count.
void makeNoiseInputs(const FeatureMap& signal, const FeatureMap& meanSquares, int spp, int saturationSpp,
                     float exposure, FeatureMap& noise);

}  // namespace affinity
