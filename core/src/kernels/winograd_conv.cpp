#include "kernels/winograd_conv.h"

#include <algorithm>
#include <string>

#include "affinity/error.h"
#include "kernels/aligned_allocator.h"
#include "kernels/simd8.h"
#include "kernels/winograd_tiles.h"
#include "kernels/winograd_products.h"
#include "kernels/winograd_transforms.h"

namespace affinity {
namespace {

constexpr int kRows = kWinogradRows;    // output pixels per tile side
constexpr int kPatch = kWinogradPatch;  // input pixels per tile side
constexpr int kPositions = kPatch * kPatch;

// Tiles transformed at a time: 48 output columns. Their transformed input (36 x 12 x inChannels
// floats, 108 KiB at 64 channels) stays in L2 while each position's 1x1 convolution streams
// through it; 12 is a whole number of the kernel's register blocks (12 and 6 pixels).
constexpr int kTilesPerTask = 12;

// G (6x3) takes a kernel row to U (points 0, 1, -1, 2, -2, infinity; Lavin and Gray); the
// input and output transforms B^T and A^T are in winograd_transforms.h.
constexpr double kG[kPatch][3] = {{1.0 / 4, 0, 0},
                                  {-1.0 / 6, -1.0 / 6, -1.0 / 6},
                                  {-1.0 / 6, 1.0 / 6, -1.0 / 6},
                                  {1.0 / 24, 1.0 / 12, 1.0 / 6},
                                  {1.0 / 24, -1.0 / 12, 1.0 / 6},
                                  {0, 0, 1}};

}  // namespace

WinogradConv::WinogradConv(const float* torchWeights, const float* bias, int outChannels, int inChannels, ConvIsa isa,
                           Precision precision)
    : out_(outChannels), in_(inChannels), bias_(std::size_t(std::max(outChannels, 0)), 0.0f) {
    if (outChannels <= 0 || inChannels <= 0)
        throw Error("Winograd convolution: unsupported shape [" + std::to_string(outChannels) + ", " +
                    std::to_string(inChannels) + ", 3, 3]");
    if (bias) std::copy(bias, bias + outChannels, bias_.begin());
    // U = G g G^T per (output, input) channel, in double and rounded once; stored per position
    // in torch's 1x1 layout [out][in].
    std::vector<std::vector<float>> u(kPositions, std::vector<float>(std::size_t(outChannels) * inChannels));
    for (int o = 0; o < outChannels; ++o)
        for (int c = 0; c < inChannels; ++c) {
            const float* g = torchWeights + (std::size_t(o) * inChannels + c) * 9;
            for (int i = 0; i < kPatch; ++i)
                for (int j = 0; j < kPatch; ++j) {
                    double sum = 0.0;
                    for (int a = 0; a < 3; ++a)
                        for (int b = 0; b < 3; ++b) sum += kG[i][a] * double(g[a * 3 + b]) * kG[j][b];
                    u[std::size_t(i * kPatch + j)][std::size_t(o) * inChannels + c] = float(sum);
                }
        }
    for (int p = 0; p < kPositions; ++p)
        positions_[std::size_t(p)] = PackedConv(u[std::size_t(p)].data(), nullptr, outChannels, inChannels, 1, isa);
    bf16Positions_ = bf16Positions(u, outChannels, inChannels, precision == Precision::BFloat16);
    transforms_ = {winograd_lines::transformPatch<Float8>, winograd_lines::transformOutput<Float8>};
#if AFFINITY_HAVE_AVX512_KERNEL
    if (isa == ConvIsa::Avx512) transforms_ = winogradTransformsAvx512();    // PackedConv checked the CPU
    if (!bf16Positions_.empty()) patchBf16_ = winogradPatchTransformBf16();  // bf16Positions checked the CPU
#endif
}

void WinogradConv::strip(const ConvSource* sources, int sourceCount, int height, int width, int tileY, int x0, int x1,
                         Activation activation, bool add, float* const* rows) const {
    // Per thread, reused from call to call: the transformed input and products of kTilesPerTask
    // tiles, a border tile's patch, and where the outputs outside the rows and columns asked for go.
    thread_local AlignedVector<float> v, m;
    thread_local AlignedVector<std::uint16_t> rounded;  // V in bfloat16, for bf16Positions_
    thread_local std::vector<float> patch, discard;
    const std::size_t inPlane = std::size_t(kTilesPerTask) * in_, outPlane = std::size_t(kTilesPerTask) * out_;
    const bool bf16 = patchBf16_ != nullptr;
    if (!bf16 && v.size() < kPositions * inPlane) v.resize(kPositions * inPlane);
    if (bf16 && rounded.size() < kPositions * inPlane) rounded.resize(kPositions * inPlane);
    if (m.size() < kPositions * outPlane) m.resize(kPositions * outPlane);
    if (patch.size() < kPositions * std::size_t(in_)) patch.resize(kPositions * std::size_t(in_));
    if (discard.size() < std::size_t(out_)) discard.resize(std::size_t(out_), 0.0f);
    const bool leaky = activation == Activation::LeakyRelu;
    const int endTile = (x1 + kRows - 1) / kRows;
    for (int firstTile = x0 / kRows; firstTile < endTile; firstTile += kTilesPerTask) {
        const int tiles = std::min(kTilesPerTask, endTile - firstTile);
        for (int t = 0; t < tiles; ++t) {
            std::size_t offset = std::size_t(t) * in_;  // of this source's channels in the tile's V
            for (int s = 0; s < sourceCount; ++s) {
                const float* patchRow[kPatch];
                const std::size_t stride = winograd::patchRows<kPatch>(
                    sources[s], height, width, kRows * tileY - 1, kRows * (firstTile + t) - 1, patch.data(), patchRow);
                if (bf16)
                    patchBf16_(patchRow, stride, sources[s].channels, inPlane, rounded.data() + offset);
                else
                    transforms_.patch(patchRow, stride, sources[s].channels, inPlane, v.data() + offset);
                offset += std::size_t(sources[s].channels);
            }
        }
        if (bf16)
            winogradProducts(bf16Positions_, rounded.data(), inPlane, tiles, m.data(), outPlane);
        else
            winogradProducts(positions_.data(), kPositions, v.data(), inPlane, tiles, m.data(), outPlane);
        for (int t = 0; t < tiles; ++t) {
            const int x = kRows * (firstTile + t);
            float* out[kRows][kRows];
            for (int r = 0; r < kRows; ++r)
                for (int q = 0; q < kRows; ++q) {
                    const bool wanted = rows[r] && x + q >= x0 && x + q < x1;
                    out[r][q] = wanted ? rows[r] + std::size_t(x + q) * out_ : discard.data();
                }
            transforms_.output(m.data() + std::size_t(t) * out_, outPlane, bias_.data(), out_, leaky, add, out);
        }
    }
}

void WinogradConv::apply(const ConvSource* sources, int sourceCount, int height, int width, Activation activation,
                         FeatureMap& output, bool parallel) const {
    const int tileRows = (height + kRows - 1) / kRows, tileColumns = (width + kRows - 1) / kRows;
    const int chunks = (tileColumns + kTilesPerTask - 1) / kTilesPerTask;
    const long long tasks = (long long)tileRows * chunks;
#pragma omp parallel for schedule(dynamic) if (parallel)
    for (long long task = 0; task < tasks; ++task) {
        const int tileY = int(task / chunks);
        const int x0 = int(task % chunks) * kRows * kTilesPerTask;
        const int x1 = std::min(width, x0 + kRows * kTilesPerTask);
        float* rows[kRows];
        for (int r = 0; r < kRows; ++r) {
            const int y = kRows * tileY + r;
            rows[r] = y < height ? output.pixel(y, 0) : nullptr;
        }
        strip(sources, sourceCount, height, width, tileY, x0, x1, activation, false, rows);
    }
}

}  // namespace affinity
