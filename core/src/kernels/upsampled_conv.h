#pragma once
// The decoder's 3x3 convolution over concat(upsampleNearest(coarse), skip) without the
// multiply-adds that the upsampling makes redundant. An output pixel's nine taps into the
// upsampled map fall on only 2x2 coarse pixels (which ones depends on the pixel's row and
// column parity), so per parity the coarse part is a 2x2 convolution over the coarse level with
// the folded weights: 4 taps instead of 9 over those channels. The skip part stays an ordinary
// 3x3 convolution added onto it, directly (row) or, kWinogradRows rows at a time, both parts in
// Winograd forms (rowGroup: coarse_winograd.h and winograd_conv.h). The same function as
// Conv2d's unfolded path up to float rounding (the folded weights are sums), not bit for bit.
#include "kernels/coarse_winograd.h"
#include "kernels/conv_kernel.h"
#include "kernels/winograd_conv.h"

namespace affinity {

class UpsampledConv {
public:
    // torchWeights [outChannels][coarseChannels + skipChannels][3][3] (the coarse channels first),
    // bias [outChannels]. `precision` applies to the Winograd forms of rowGroup.
    UpsampledConv(const float* torchWeights, const float* bias, int outChannels, int coarseChannels, int skipChannels,
                  ConvIsa isa, Precision precision = Precision::Float32);

    int coarseChannels() const { return phase_[0][0].inChannels(); }

    // Output row y, columns [x0, x1), of act(conv(concat(upsampled coarse, skip)) + bias) for
    // height x width images, as convolveRow(full, {coarse, skip}, ...) computes it; `full` is the
    // same convolution packed whole, for the pixels of an odd last row or column (below).
    void row(const PackedConv& full, const ConvSource& coarse, const ConvSource& skip, int height, int width, int y,
             int x0, int x1, Activation activation, float* outRow) const;
    // Rows kWinogradRows * tileY + r into rows[r], r < kWinogradRows (null past the image), at
    // once, both parts in Winograd forms: equal to row() up to float rounding.
    void rowGroup(const PackedConv& full, const ConvSource& coarse, const ConvSource& skip, int height, int width,
                  int tileY, int x0, int x1, Activation activation, float* const* rows) const;

private:
    // The coarse part of output row y (with the bias, before the activation).
    void coarseRow(const ConvSource& coarse, int height, int width, int y, int x0, int x1, float* outRow) const;
    // Redoes, unfolded, the pixels of row y that the folded form gets wrong: all of an odd
    // height's last row, an odd width's last column.
    void unfoldedEdges(const PackedConv& full, const ConvSource& coarse, const ConvSource& skip, int height, int width,
                       int y, int x0, int x1, Activation activation, float* outRow) const;

    PackedConv phase_[2][2];         // [row parity][column parity]: 2x2 over the coarse level, with the bias
    PackedConv skip_;                // 3x3 over the skip input, no bias
    WinogradConv skipWinograd_;      // the same in the Winograd form
    CoarseWinograd coarseWinograd_;  // the phases' coarse part in the Winograd form
};

}  // namespace affinity
