#pragma once
// What the denoiser accumulates over time and filters (docs/MODEL.md sections 1, 3, 6, 7): the
// noisy radiance L_t, the mean over a pixel's samples of diffuse + specular, 3 channels. The
// filtered signal is the output radiance itself.
#include "kernels/feature_map.h"

namespace affinity {

// Channels of the accumulated and filtered signal: RGB radiance.
constexpr int kSignalChannels = 3;

// sums: Embedding's per-pixel sample sums over `spp` samples. signal: height x width x
// kSignalChannels.
void makeAccumulatedSignal(const FeatureMap& sums, int spp, FeatureMap& signal);
// The same for `pixels` consecutive pixels' sums, on the calling thread: for sums made a chunk
// at a time that need not be kept (Embedding::apply with a SumsSink).
void signalFromSums(const float* sums, long long pixels, int spp, float* signal);

// Per pixel, the mean over its `spp` samples of one of the sums: Embedding::kSumLuminanceSquares
// for the noise of the signal (docs/MODEL.md section 10, "Input fallback"),
// Embedding::kSumEmissive for the share of its samples that saw an emitter ("Peak guard").
// means: height x width x 1, at most 1e30.
void makeSampleMeans(const FeatureMap& sums, int spp, int sum, FeatureMap& means);
// The same for `pixels` consecutive pixels' sums, on the calling thread.
void sampleMeansFromSums(const float* sums, long long pixels, int spp, int sum, float* means);

}  // namespace affinity
