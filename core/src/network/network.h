#pragma once
// The network of docs/MODEL.md as inference objects, built from a weights file.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "affinity/precision.h"
#include "network/embedding.h"
#include "network/unet_layers.h"

namespace affinity {

class Weights;

// The largest config.temporal_gain_percent a weights file may set.
inline constexpr int kMaxTemporalGainPercent = 10000;

struct Network {
    std::string source;
    std::optional<Embedding> embedding;
    std::vector<int> embeddingWidths;          // inputs of layer 0, then each layer's outputs
    std::vector<std::vector<Conv2d>> encoder;  // [level][conv]
    std::vector<Conv2d> bottleneck;
    std::vector<std::vector<Conv2d>> decoder;  // [level][conv], level 0 = full resolution
    std::optional<Conv2d> head;                // 1x1 convolution to headChannels()
    int kernels = 3, affinityFeatures = 8, tapSize = 5;
    // Whether the Denoiser restores light after the kernels (config.light_restoration, docs/MODEL.md
    // sections 8 and 10): a property of the trained weights, set where it was measured to help.
    bool lightRestoration = false;
    // What each valid temporal tap's weight is multiplied by (config.temporal_gain_percent / 100,
    // docs/MODEL.md sections 7-8): how far the last kernel trusts the previous output against the
    // frame's own; 1 where the file does not set it.
    float temporalGain = 1.0f;
    std::int64_t parameterCount = 0;
    Precision precision = Precision::Float32;  // of the products (affinity/precision.h), never Auto

    // Head channels per kernel: features, bandwidth, centre weight.
    int kernelChannels() const { return affinityFeatures + 2; }
    // Head output channels: K kernelChannels() + 2 (temporal bandwidth, lambda).
    int headChannels() const { return kernels * kernelChannels() + 2; }
};

// Throws affinity::Error naming the source and the first inconsistency, or where
// Precision::BFloat16 is asked for on a CPU without AVX512-BF16.
// Precision::Auto is resolved (resolvePrecision).
Network buildNetwork(const Weights& weights, Precision precision = Precision::Float32);

}  // namespace affinity
