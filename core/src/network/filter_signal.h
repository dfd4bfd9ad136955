#pragma once
// What the denoiser accumulates over time and filters (docs/MODEL.md sections 1, 3, 6, 7). The
// accumulated signal holds first the channels the kernels filter - the noisy radiance, or with
// albedo demodulation the diffuse radiance divided by the albedo and the specular radiance -
// then channels that are only accumulated: the albedo, multiplied back after filtering so that
// texture detail need not survive the kernels, and with emission bypass the radiance of
// emissive samples, added back so that a light smaller than a pixel is not spread around.
#include "kernels/feature_map.h"

namespace affinity {

// Albedo below this divides (and multiplies back) as this: the quotient stays bounded, and a
// kernel that spreads a dark pixel's light onto a bright neighbour amplifies it at most 1 / 0.1
// times (with 0.01, fireflies on dark surfaces became bright blotches: relMSE 13 on the
// benchmark's fireflies scene against 1.1 without demodulation, docs/TRAINING.md).
constexpr float kDemodulationFloor = 0.1f;

// Where each part sits in the accumulated signal of a model.
struct SignalLayout {
    bool albedoDemodulation = false;
    bool emissionBypass = false;

    int filteredChannels() const { return albedoDemodulation ? 6 : 3; }
    int unfilteredChannels() const { return (albedoDemodulation ? 3 : 0) + (emissionBypass ? 3 : 0); }
    int channels() const { return filteredChannels() + unfilteredChannels(); }
};

// sums: Embedding's per-pixel sample sums over `spp` samples. signal: height x width x
// layout.channels().
void makeAccumulatedSignal(const FeatureMap& sums, int spp, const SignalLayout& layout, FeatureMap& signal);
// The same for `pixels` consecutive pixels' sums, on the calling thread: for sums made a chunk
// at a time that need not be kept (Embedding::apply with a SumsSink).
void signalFromSums(const float* sums, long long pixels, int spp, const SignalLayout& layout, float* signal);

// Radiance from a filtered signal and the accumulated signal it came from, whose unfiltered
// channels hold the albedo to multiply back onto the diffuse light and the emitted radiance to
// add. out: pixelCount() x 3 floats.
void radianceFromSignal(const FeatureMap& filtered, const FeatureMap& accumulated, const SignalLayout& layout,
                        float* out);

}  // namespace affinity
