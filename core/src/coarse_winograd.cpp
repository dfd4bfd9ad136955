#include "coarse_winograd.h"

#include <algorithm>

#include "aligned_allocator.h"
#include "simd8.h"
#include "winograd_conv.h"
#include "winograd_tiles.h"
#include "winograd_transforms.h"

namespace affinity {
namespace {

// Partial loads and stores over a channel tail, shared with the F(4x4, 3x3) transforms.
using winograd_lines::storeLanes;
inline Float8 loadLanes(const float* p, int count) { return winograd_lines::loadLanes<Float8>(p, count); }

static_assert(kWinogradRows == 4, "a group of four full-resolution rows is two coarse rows per parity");

// Tiles (2x2 coarse positions) transformed at a time.
constexpr int kTilesPerTask = 24;

// V = B^T d B, B^T = [1 -1 0; 0 1 0; 0 -1 1], for the `channels` channels of a 3x3 patch
// (pixel (i, j) at rows[i] + j * pixelStride); position i * 3 + j goes to dst + (i * 3 + j) * plane.
void transformPatch(const float* const (&rows)[3], std::size_t pixelStride, int channels, std::size_t plane,
                    float* dst) {
    for (int c = 0; c < channels; c += 8) {
        const int lanes = std::min(8, channels - c);
        Float8 across[3][3];
        for (int i = 0; i < 3; ++i) {
            const Float8 d0 = loadLanes(rows[i] + c, lanes), d1 = loadLanes(rows[i] + pixelStride + c, lanes);
            const Float8 d2 = loadLanes(rows[i] + 2 * pixelStride + c, lanes);
            across[i][0] = d0 - d1;
            across[i][1] = d1;
            across[i][2] = d2 - d1;
        }
        for (int j = 0; j < 3; ++j) {
            storeLanes(across[0][j] - across[1][j], dst + std::size_t(j) * plane + c, lanes);
            storeLanes(across[1][j], dst + std::size_t(3 + j) * plane + c, lanes);
            storeLanes(across[2][j] - across[1][j], dst + std::size_t(6 + j) * plane + c, lanes);
        }
    }
}

// Y = A^T M A + bias, A^T = [1 1 0; 0 1 1], for `channels` output channels of one tile; position
// (i, j) of M at m + (i * 3 + j) * plane; output (r, q) to out[r][q].
void transformOutput(const float* m, std::size_t plane, const float* bias, int channels,
                     float* const (&out)[2][2]) {
    for (int o = 0; o < channels; o += 8) {
        const int lanes = std::min(8, channels - o);
        Float8 down[2][3];
        for (int j = 0; j < 3; ++j) {
            const Float8 m0 = loadLanes(m + std::size_t(j) * plane + o, lanes);
            const Float8 m1 = loadLanes(m + std::size_t(3 + j) * plane + o, lanes);
            const Float8 m2 = loadLanes(m + std::size_t(6 + j) * plane + o, lanes);
            down[0][j] = m0 + m1;
            down[1][j] = m1 + m2;
        }
        const Float8 b = loadLanes(bias + o, lanes);
        for (int r = 0; r < 2; ++r) {
            storeLanes(down[r][0] + down[r][1] + b, out[r][0] + o, lanes);
            storeLanes(down[r][1] + down[r][2] + b, out[r][1] + o, lanes);
        }
    }
}

}  // namespace

CoarseWinograd::CoarseWinograd(const std::vector<double> (&phaseWeights)[2][2], const float* bias, int outChannels,
                               int coarseChannels, ConvIsa isa)
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
        }
}

void CoarseWinograd::rows(const float* coarse, int height, int width, int y0, int x0, int x1,
                          float* const* rows) const {
    thread_local AlignedVector<float> v, m;
    thread_local std::vector<float> patch, discard;
    const std::size_t inPlane = std::size_t(kTilesPerTask) * in_, outPlane = std::size_t(kTilesPerTask) * out_;
    if (v.size() < 9 * inPlane) v.resize(9 * inPlane);
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
                    const std::size_t stride = winograd::patchRows<3>(
                        source, coarseHeight, coarseWidth, coarseRow + firstCoarseTap(py),
                        2 * (firstTile + t) + firstCoarseTap(px), patch.data(), patchRow);
                    transformPatch(patchRow, stride, in_, inPlane, v.data() + std::size_t(t) * in_);
                }
                for (int p = 0; p < 9; ++p) {
                    const ConvSource position{v.data() + std::size_t(p) * inPlane, in_};
                    convolveRow(positions_[py][px][std::size_t(p)], &position, 1, 1, tiles, 0, 0, tiles,
                                Activation::None, m.data() + std::size_t(p) * outPlane);
                }
                for (int t = 0; t < tiles; ++t) {
                    float* out[2][2];
                    for (int r = 0; r < 2; ++r)
                        for (int q = 0; q < 2; ++q) {
                            const int j = 2 * (firstTile + t) + q;
                            const bool wanted = outRows[r] && j >= j0 && j < j1;
                            out[r][q] = wanted ? outRows[r] + std::size_t(2 * j + px) * out_ : discard.data();
                        }
                    transformOutput(m.data() + std::size_t(t) * out_, outPlane, bias_.data(), out_, out);
                }
            }
        }
    }
}

}  // namespace affinity
