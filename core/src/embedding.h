#pragma once
// The per-sample embedding network of docs/MODEL.md section 2 and the input transform of
// section 1: every sample's 18 features through a small MLP, averaged per pixel.
#include <vector>

#include "feature_map.h"

namespace affinity {

struct DenseLayer {
    int in = 0, out = 0;
    std::vector<float> weight;  // [out][in], torch layout
    std::vector<float> bias;    // [out]
};

class Embedding {
public:
    explicit Embedding(std::vector<DenseLayer> layers);  // validates chained sizes
    int outChannels() const;
    const std::vector<DenseLayer>& layers() const { return layers_; }

    // samples: [pixels][spp][kFeatureCount] raw features (frame layout); depthScale from
    // section 1. Writes the per-pixel mean embedding to `output` (height x width x E).
    // Non-finite or negative radiance is treated as 0; returns how many radiance values were.
    long long apply(const float* samples, int height, int width, int spp, float depthScale,
                    FeatureMap& output) const;

private:
    std::vector<DenseLayer> layers_;
};

}  // namespace affinity
