#pragma once
// The U-Net's layers on NHWC FeatureMaps: 3x3 and 1x1 convolutions (optionally reading the
// channel concatenation of two inputs without copying it), 2x2 max pooling with ceil mode,
// nearest-neighbour upsampling. Semantics: docs/MODEL.md section 4. Multithreaded (OpenMP)
// and vectorised; results do not depend on the thread count.
#include <vector>

#include "feature_map.h"

namespace affinity {

enum class Activation { None, LeakyRelu };  // leaky ReLU slope 0.01

// A convolution's weights, repacked once at load time for the kernel's access pattern.
class Conv2d {
public:
    // torchWeights: [outChannels][inChannels][size][size] (torch layout); size is 1 or 3.
    Conv2d(const float* torchWeights, const float* bias, int outChannels, int inChannels, int size);

    int inChannels() const { return in_; }
    int outChannels() const { return out_; }
    int size() const { return size_; }

    // output = act(conv(input) + bias), zero padding (size / 2). output is resized.
    void apply(const FeatureMap& input, Activation activation, FeatureMap& output) const;
    // The same on concat(first, second) along channels (first's channels first): what the
    // decoder does with its skip connections, without materialising the concatenation.
    void apply(const FeatureMap& first, const FeatureMap& second, Activation activation, FeatureMap& output) const;

private:
    int out_, in_, size_;
    std::vector<float> packed_;  // layout chosen by the implementation
    std::vector<float> bias_;
};

// out(y, x) = max over in(2y..2y+1, 2x..2x+1) that exist; out is ceil(h/2) x ceil(w/2).
void maxPool2x2(const FeatureMap& input, FeatureMap& output);
// out(y, x) = in(y / 2, x / 2) for an output of height x width.
void upsampleNearest(const FeatureMap& input, int height, int width, FeatureMap& output);

}  // namespace affinity
