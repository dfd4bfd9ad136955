#include "kernels/upsampled_conv.h"

#include <vector>

namespace affinity {
namespace {

// Which of the two coarse rows tap `offset` (-1, 0, +1) of a row of this parity falls on.
int foldedTap(int parity, int offset) { return (parity + offset + 2) / 2 - 1 - firstCoarseTap(parity); }

}  // namespace

UpsampledConv::UpsampledConv(const float* torchWeights, const float* bias, int outChannels, int coarseChannels,
                             int skipChannels, ConvIsa isa, Precision precision) {
    const int in = coarseChannels + skipChannels;
    auto weight = [&](int o, int c, int ky, int kx) {
        return torchWeights[((std::size_t(o) * in + c) * 3 + ky) * 3 + kx];
    };
    std::vector<double> phaseWeights[2][2];
    for (int py = 0; py < 2; ++py)
        for (int px = 0; px < 2; ++px) {
            std::vector<double>& folded = phaseWeights[py][px];
            folded.assign(std::size_t(outChannels) * coarseChannels * 4, 0.0);
            for (int o = 0; o < outChannels; ++o)
                for (int c = 0; c < coarseChannels; ++c)
                    for (int ky = 0; ky < 3; ++ky)
                        for (int kx = 0; kx < 3; ++kx)
                            folded[((std::size_t(o) * coarseChannels + c) * 2 + foldedTap(py, ky - 1)) * 2 +
                                   foldedTap(px, kx - 1)] += weight(o, c, ky, kx);
            const std::vector<float> packed(folded.begin(), folded.end());
            phase_[py][px] = PackedConv(packed.data(), bias, outChannels, coarseChannels, 2, isa);
        }
    std::vector<float> skipWeights(std::size_t(outChannels) * skipChannels * 9);
    for (int o = 0; o < outChannels; ++o)
        for (int c = 0; c < skipChannels; ++c)
            for (int k = 0; k < 9; ++k)
                skipWeights[(std::size_t(o) * skipChannels + c) * 9 + k] = weight(o, coarseChannels + c, k / 3, k % 3);
    skip_ = PackedConv(skipWeights.data(), nullptr, outChannels, skipChannels, 3, isa);
    skipWinograd_ = WinogradConv(skipWeights.data(), nullptr, outChannels, skipChannels, isa, precision);
    coarseWinograd_ = CoarseWinograd(phaseWeights, bias, outChannels, coarseChannels, isa, precision);
}

void UpsampledConv::coarseRow(const ConvSource& coarse, int height, int width, int y, int x0, int x1,
                              float* outRow) const {
    const int out = skip_.outChannels();
    const int py = y % 2;
    // One column parity at a time: output columns 2j + px are coarse columns j of a 2x2
    // convolution, written every other pixel.
    const ConvSource coarseLevel{coarse.data, coarse.channels};
    for (int px = 0; px < 2; ++px) {
        const int j0 = (x0 - px + 1) / 2, j1 = (x1 - px + 1) / 2;  // 2j + px in [x0, x1)
        if (j0 >= j1) continue;
        const ConvPlacement strided{firstCoarseTap(py), firstCoarseTap(px), 2 * out, false};
        convolveRowPlaced(phase_[py][px], &coarseLevel, 1, (height + 1) / 2, (width + 1) / 2, y / 2, j0, j1,
                          Activation::None, strided, outRow + std::size_t(px) * out);
    }
}

void UpsampledConv::unfoldedEdges(const PackedConv& full, const ConvSource& coarse, const ConvSource& skip, int height,
                                  int width, int y, int x0, int x1, Activation activation, float* outRow) const {
    // An odd height's last row (an odd width's last column) has no full-resolution row below it,
    // but its folded tap +1 reads the coarse row it lies on.
    const ConvSource both[2] = {coarse, skip};
    if (height % 2 == 1 && y == height - 1)
        convolveRow(full, both, 2, height, width, y, x0, x1, activation, outRow);
    else if (width % 2 == 1 && x1 == width)
        convolveRow(full, both, 2, height, width, y, width - 1, width, activation, outRow);
}

void UpsampledConv::row(const PackedConv& full, const ConvSource& coarse, const ConvSource& skip, int height, int width,
                        int y, int x0, int x1, Activation activation, float* outRow) const {
    coarseRow(coarse, height, width, y, x0, x1, outRow);
    const ConvPlacement added{-1, -1, skip_.outChannels(), true};
    convolveRowPlaced(skip_, &skip, 1, height, width, y, x0, x1, activation, added, outRow);
    unfoldedEdges(full, coarse, skip, height, width, y, x0, x1, activation, outRow);
}

void UpsampledConv::rowGroup(const PackedConv& full, const ConvSource& coarse, const ConvSource& skip, int height,
                             int width, int tileY, int x0, int x1, Activation activation, float* const* rows) const {
    const int y0 = kWinogradRows * tileY;
    coarseWinograd_.rows(coarse.data, height, width, y0, x0, x1, rows);
    skipWinograd_.strip(&skip, 1, height, width, tileY, x0, x1, activation, true, rows);
    for (int r = 0; r < kWinogradRows; ++r)
        if (rows[r]) unfoldedEdges(full, coarse, skip, height, width, y0 + r, x0, x1, activation, rows[r]);
}

}  // namespace affinity
