#pragma once
// The coarse part of the decoder's folded convolution (upsampled_conv.h) in the Winograd form
// F(2x2, 2x2): for each row and column parity of the full-resolution output, the 2x2
// convolution over the coarse level computes each 2x2 block of its coarse positions from a 3x3
// patch with 9 multiply-adds per channel pair instead of 16 (V = B^T d B, the 9 positions' 1x1
// convolutions on the kernel of conv_kernel.h, A^T M A + bias; every coefficient is 0 or +-1).
// Four full-resolution rows at a time: two coarse rows for each row parity.
#include <array>
#include <vector>

#include "affinity/precision.h"
#include "kernels/bf16_gemm.h"
#include "kernels/coarse_winograd_transforms.h"
#include "kernels/conv_kernel.h"

namespace affinity {

// The first of the two coarse rows (columns) that the folded taps of a full-resolution row
// (column) of this parity read, relative to its own coarse row: row 2i reads coarse rows i - 1
// (tap -1) and i (taps 0, +1); row 2i + 1 reads i (taps -1, 0) and i + 1 (tap +1).
inline int firstCoarseTap(int parity) { return parity == 0 ? -1 : 0; }

class CoarseWinograd {
public:
    CoarseWinograd() = default;
    // phaseWeights[py][px]: the folded 2x2 weights of that row and column parity, torch layout
    // [outChannels][coarseChannels][2][2]; bias [outChannels] or null (zero).
    CoarseWinograd(const std::vector<double> (&phaseWeights)[2][2], const float* bias, int outChannels,
                   int coarseChannels, ConvIsa isa, Precision precision = Precision::Float32);

    // Full-resolution rows y0 + r, r < 4 (y0 a multiple of 4), columns [x0, x1), of a height x
    // width output: the coarse part with the bias and no activation, into rows[r] (column 0 of an
    // NHWC row; null for a row not wanted). `coarse` is (height + 1) / 2 x (width + 1) / 2.
    void rows(const float* coarse, int height, int width, int y0, int x0, int x1, float* const* rows) const;

private:
    int out_ = 0, in_ = 0;
    std::array<PackedConv, 9> positions_[2][2];        // [py][px][position i * 3 + j]
    std::vector<PackedGemmBf16> bf16Positions_[2][2];  // the same in bfloat16 (Precision::BFloat16)
    CoarsePatchTransformBf16 patchBf16_ = nullptr;     // set with bf16Positions_
    std::vector<float> bias_;
    CoarseWinogradTransforms transforms_{};  // of the instruction set's vector width
};

}  // namespace affinity
