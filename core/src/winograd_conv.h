#pragma once
// A 3x3 convolution (zero padding 1, stride 1) in the Winograd form F(2x2, 3x3) (Lavin and
// Gray, "Fast Algorithms for Convolutional Neural Networks", 2016): each 2x2 block of output
// pixels is computed from its 4x4 input patch with 16 multiply-adds per (input, output) channel
// pair instead of 36. Per 2x2 tile and input channel the patch d becomes V = B^T d B (additions
// only); for each of the 16 positions of V the tiles' V go through a 1x1 convolution with the
// transformed weights U = G g G^T (the register-blocked kernel of conv_kernel.h, so the same
// vector widths and the same bitwise agreement between them); the 2x2 output is A^T M A + bias.
// With the interpolation points 0, 1 and -1 every transform is sums and halvings, so the result
// is the direct convolution's up to float rounding of the same order, not bit for bit.
#include <array>
#include <vector>

#include "conv_kernel.h"
#include "feature_map.h"

namespace affinity {

class WinogradConv {
public:
    WinogradConv() = default;
    // torchWeights [outChannels][inChannels][3][3], bias [outChannels] or null (zero).
    WinogradConv(const float* torchWeights, const float* bias, int outChannels, int inChannels, ConvIsa isa);

    int outChannels() const { return out_; }
    int inChannels() const { return in_; }

    // output (height x width x outChannels, already sized) = act(conv3x3(concat(sources)) + bias),
    // the sources as conv_kernel.h's ConvSource (an upsampled one is read at (y / 2, x / 2)).
    // With `parallel`, multithreaded over pieces of 2-row strips of tiles; each output pixel is
    // computed by one thread in a fixed order, so the thread count changes no value.
    void apply(const ConvSource* sources, int sourceCount, int height, int width, Activation activation,
               FeatureMap& output, bool parallel) const;
    // Output rows 2 * tileY and 2 * tileY + 1, columns [x0, x1), on the calling thread,
    // into rows[0] and rows[1] (column 0 of NHWC rows of outChannels; rows[1] null where the
    // image has no such row). With `add`, onto the values there: act(there + conv + bias).
    // Each pixel's value does not depend on the column range it was computed in.
    void strip(const ConvSource* sources, int sourceCount, int height, int width, int tileY, int x0, int x1,
               Activation activation, bool add, float* const (&rows)[2]) const;

private:
    int out_ = 0, in_ = 0;
    std::array<PackedConv, 16> positions_;  // 1x1 convolutions by U at V's position i * 4 + j
    std::vector<float> bias_;
};

}  // namespace affinity
