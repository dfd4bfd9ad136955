#pragma once
// A 3x3 convolution (zero padding 1, stride 1) in the Winograd form F(4x4, 3x3) (Lavin and
// Gray, "Fast Algorithms for Convolutional Neural Networks", 2016): each 4x4 block of output
// pixels is computed from its 6x6 input patch with 36 multiply-adds per (input, output) channel
// pair instead of 144. Per tile and input channel the patch d becomes V = B^T d B; for each of
// the 36 positions of V the tiles' V go through a 1x1 convolution with the transformed weights
// U = G g G^T (the register-blocked kernel of conv_kernel.h, so the same vector widths and the
// same bitwise agreement between them); the 4x4 output is A^T M A + bias. The interpolation
// points 0, +-1, +-2 keep the transforms' coefficients small (at most 8): the result is the direct
// convolution's up to float rounding a few times larger than the direct form's, well inside
// the layer tests' 1e-5 of the terms' magnitudes.
#include <array>
#include <vector>

#include "affinity/precision.h"
#include "kernels/bf16_gemm.h"
#include "kernels/conv_kernel.h"
#include "kernels/feature_map.h"
#include "kernels/winograd_transforms.h"  // kWinogradRows: output rows (and columns) of a tile

namespace affinity {

class WinogradConv {
public:
    WinogradConv() = default;
    // torchWeights [outChannels][inChannels][3][3], bias [outChannels] or null (zero). With
    // Precision::BFloat16 the per-position products are taken in bfloat16 (winograd_products.h).
    WinogradConv(const float* torchWeights, const float* bias, int outChannels, int inChannels, ConvIsa isa,
                 Precision precision = Precision::Float32);

    int outChannels() const { return out_; }
    int inChannels() const { return in_; }

    // output (height x width x outChannels, already sized) = act(conv3x3(concat(sources)) + bias),
    // the sources as conv_kernel.h's ConvSource (an upsampled one is read at (y / 2, x / 2)).
    // With `parallel`, multithreaded over pieces of strips of kWinogradRows rows; each output
    // pixel is computed by one thread in a fixed order, so the thread count changes no value.
    void apply(const ConvSource* sources, int sourceCount, int height, int width, Activation activation,
               FeatureMap& output, bool parallel) const;
    // Output rows kWinogradRows * tileY + r, columns [x0, x1), on the calling thread, into rows[r],
    // r < kWinogradRows (column 0 of an NHWC row of outChannels; null for a row not wanted). With
    // `add`, onto the values there: act(there + conv + bias). Each pixel's value does not depend
    // on the column range it was computed in.
    void strip(const ConvSource* sources, int sourceCount, int height, int width, int tileY, int x0, int x1,
               Activation activation, bool add, float* const* rows) const;

private:
    int out_ = 0, in_ = 0;
    // 1x1 convolutions by U at V's position i * kWinogradPatch + j
    std::array<PackedConv, kWinogradPatch * kWinogradPatch> positions_;
    // The same in bfloat16 (Precision::BFloat16; empty otherwise)
    std::vector<PackedGemmBf16> bf16Positions_;
    WinogradPatchTransformBf16 patchBf16_ = nullptr;  // set with bf16Positions_
    std::vector<float> bias_;
    WinogradTransforms transforms_{};  // of the instruction set's vector width
};

}  // namespace affinity
