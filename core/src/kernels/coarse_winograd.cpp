#include "kernels/coarse_winograd.h"

#include <algorithm>

#include "kernels/aligned_allocator.h"
#include "kernels/coarse_winograd_transforms.h"
#include "kernels/simd8.h"
#include "kernels/winograd_conv.h"
#include "kernels/winograd_products.h"
#include "kernels/winograd_tiles.h"

namespace affinity {
namespace {

static_assert(kWinogradRows == 4, "a group of four full-resolution rows is two coarse rows per parity");

// Tiles (2x2 coarse positions) transformed at a time.
constexpr int kTilesPerTask = 24;

}  // namespace

CoarseWinograd::CoarseWinograd(const std::vector<double> (&phaseWeights)[2][2], const float* bias, int outChannels,
                               int coarseChannels, ConvIsa isa, Precision precision)
    : out_(outChannels), in_(coarseChannels), bias_(std::size_t(outChannels), 0.0f) {
    if (bias) std::copy(bias, bias + outChannels, bias_.begin());
    // U = G g G^T, G = [1 0; 1 1; 0 1], in double and rounded once.
    const double G[3][2] = {{1, 0}, {1, 1}, {0, 1}};
    for (int py = 0; py < 2; ++py)
        for (int px = 0; px < 2; ++px) {
            const std::vector<double>& w = phaseWeights[py][px];
            std::vector<std::vector<float>> u(9, std::vector<float>(std::size_t(outChannels) * coarseChannels));
            for (std::size_t oc = 0; oc < std::size_t(outChannels) * coarseChannels; ++oc) {
                const double* g = w.data() + oc * 4;
                for (int i = 0; i < 3; ++i)
                    for (int j = 0; j < 3; ++j) {
                        double sum = 0.0;
                        for (int a = 0; a < 2; ++a)
                            for (int b = 0; b < 2; ++b) sum += G[i][a] * g[a * 2 + b] * G[j][b];
                        u[std::size_t(i * 3 + j)][oc] = float(sum);
                    }
            }
            for (int p = 0; p < 9; ++p)
                positions_[py][px][std::size_t(p)] =
                    PackedConv(u[std::size_t(p)].data(), nullptr, outChannels, coarseChannels, 1, isa);
            bf16Positions_[py][px] = bf16Positions(u, outChannels, coarseChannels, precision == Precision::BFloat16);
        }
    transforms_ = {coarse_lines::transformPatch<Float8>, coarse_lines::transformOutput<Float8>};
#if AFFINITY_HAVE_AVX512_KERNEL
    if (isa == ConvIsa::Avx512) transforms_ = coarseWinogradTransformsAvx512();  // PackedConv checked the CPU
    if (!bf16Positions_[0][0].empty()) patchBf16_ = coarsePatchTransformBf16();  // bf16Positions checked the CPU
#endif
}

void CoarseWinograd::rows(const float* coarse, int height, int width, int y0, int x0, int x1,
                          float* const* rows) const {
    thread_local AlignedVector<float> v, m;
    thread_local AlignedVector<std::uint16_t> rounded;  // V in bfloat16, for bf16Positions_
    thread_local std::vector<float> patch, discard;
    const std::size_t inPlane = std::size_t(kTilesPerTask) * in_, outPlane = std::size_t(kTilesPerTask) * out_;
    const bool bf16 = patchBf16_ != nullptr;
    if (!bf16 && v.size() < 9 * inPlane) v.resize(9 * inPlane);
    if (bf16 && rounded.size() < 9 * inPlane) rounded.resize(9 * inPlane);
    if (m.size() < 9 * outPlane) m.resize(9 * outPlane);
    if (patch.size() < 9 * std::size_t(in_)) patch.resize(9 * std::size_t(in_));
    if (discard.size() < std::size_t(out_)) discard.resize(std::size_t(out_), 0.0f);
    const int coarseHeight = (height + 1) / 2, coarseWidth = (width + 1) / 2;
    const ConvSource source{coarse, in_};
    const int coarseRow = y0 / 2;  // full-resolution rows y0 + py and y0 + 2 + py read coarse rows coarseRow, + 1
    for (int py = 0; py < 2; ++py) {
        float* const outRows[2] = {rows[py], rows[2 + py]};
        for (int px = 0; px < 2; ++px) {
            const int j0 = (x0 - px + 1) / 2, j1 = (x1 - px + 1) / 2;  // 2j + px in [x0, x1)
            // Tiles at even coarse columns whatever the range, so a pixel's value does not depend on it.
            const int endTile = (j1 + 1) / 2;
            for (int firstTile = j0 / 2; firstTile < endTile; firstTile += kTilesPerTask) {
                const int tiles = std::min(kTilesPerTask, endTile - firstTile);
                for (int t = 0; t < tiles; ++t) {
                    const float* patchRow[3];
                    const std::size_t stride =
                        winograd::patchRows<3>(source, coarseHeight, coarseWidth, coarseRow + firstCoarseTap(py),
                                               2 * (firstTile + t) + firstCoarseTap(px), patch.data(), patchRow);
                    if (bf16)
                        patchBf16_(patchRow, stride, in_, inPlane, rounded.data() + std::size_t(t) * in_);
                    else
                        transforms_.patch(patchRow, stride, in_, inPlane, v.data() + std::size_t(t) * in_);
                }
                if (bf16)
                    winogradProducts(bf16Positions_[py][px], rounded.data(), inPlane, tiles, m.data(), outPlane);
                else
                    winogradProducts(positions_[py][px].data(), 9, v.data(), inPlane, tiles, m.data(), outPlane);
                for (int t = 0; t < tiles; ++t) {
                    float* out[2][2];
                    for (int r = 0; r < 2; ++r)
                        for (int q = 0; q < 2; ++q) {
                            const int j = 2 * (firstTile + t) + q;
                            const bool wanted = outRows[r] && j >= j0 && j < j1;
                            out[r][q] = wanted ? outRows[r] + std::size_t(2 * j + px) * out_ : discard.data();
                        }
                    transforms_.output(m.data() + std::size_t(t) * out_, outPlane, bias_.data(), out_, out);
                }
            }
        }
    }
}

}  // namespace affinity
