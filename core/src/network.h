#pragma once
// The network of docs/MODEL.md as inference objects, built from a weights file.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "embedding.h"
#include "unet_layers.h"

namespace affinity {

class Weights;

struct Network {
    std::string source;
    std::optional<Embedding> embedding;
    std::vector<int> embeddingWidths;          // inputs of layer 0, then each layer's outputs
    std::vector<std::vector<Conv2d>> encoder;  // [level][conv]
    std::vector<Conv2d> bottleneck;
    std::vector<std::vector<Conv2d>> decoder;  // [level][conv], level 0 = full resolution
    std::optional<Conv2d> head;                // 1x1 convolution to headChannels()
    int kernels = 3, affinityFeatures = 8, tapSize = 5;
    bool albedoDemodulation = false;  // the kernels filter diffuse / albedo and specular
    bool sourceWeights = false;       // each kernel weighs a neighbour q by a learned s(q)
    std::int64_t parameterCount = 0;

    // Head channels per kernel: features, bandwidth, centre weight (and source weight).
    int kernelChannels() const { return affinityFeatures + (sourceWeights ? 3 : 2); }
    // Head output channels: K kernelChannels() + 2 (temporal bandwidth, lambda).
    int headChannels() const { return kernels * kernelChannels() + 2; }
    // Channels of the filtered signal and of the accumulated one, which also holds the albedo
    // (core/src/filter_signal.h).
    int signalChannels() const { return albedoDemodulation ? 6 : 3; }
    int accumulatedChannels() const { return albedoDemodulation ? 9 : 3; }
};

// Throws affinity::Error naming the source and the first inconsistency.
Network buildNetwork(const Weights& weights);

}  // namespace affinity
