#include "winograd_conv.h"

#include <algorithm>
#include <string>

#include "affinity/error.h"
#include "aligned_allocator.h"
#include "simd8.h"
#include "winograd_tiles.h"

namespace affinity {
namespace {

using winograd::loadLanes;
using winograd::storeLanes;

constexpr int kRows = kWinogradRows;    // output pixels per tile side
constexpr int kPatch = kWinogradPatch;  // input pixels per tile side
constexpr int kPositions = kPatch * kPatch;

// Tiles transformed at a time: 48 output columns. Their transformed input (36 x 12 x inChannels
// floats, 108 KiB at 64 channels) stays in L2 while each position's 1x1 convolution streams
// through it; 12 is a whole number of the kernel's register blocks (12 and 6 pixels).
constexpr int kTilesPerTask = 12;

// The transforms' matrices for the points 0, 1, -1, 2, -2 (and infinity), Lavin and Gray:
// B^T (6x6) takes a patch row to V, G (6x3) a kernel row to U, A^T (4x6) a product row to the
// output. Written out below as sums, with the coefficients' common factors pulled out.
//   B^T = [4  0 -5  0 1 0;  0 -4 -4  1 1 0;  0 4 -4 -1 1 0;
//          0 -2 -1  2 1 0;  0  2 -1 -2 1 0;  0 4  0 -5 0 1]
//   A^T = [1 1 1 1 1 0;  0 1 -1 2 -2 0;  0 1 1 4 4 0;  0 1 -1 8 -8 1]
constexpr double kG[kPatch][3] = {{1.0 / 4, 0, 0},
                                  {-1.0 / 6, -1.0 / 6, -1.0 / 6},
                                  {-1.0 / 6, 1.0 / 6, -1.0 / 6},
                                  {1.0 / 24, 1.0 / 12, 1.0 / 6},
                                  {1.0 / 24, -1.0 / 12, 1.0 / 6},
                                  {0, 0, 1}};

// t = B^T d for one line of six vectors.
inline void inputLine(const Float8 (&d)[kPatch], Float8 (&t)[kPatch]) {
    const Float8 two = Float8::broadcast(2.0f), four = Float8::broadcast(4.0f), five = Float8::broadcast(5.0f);
    t[0] = four * d[0] - five * d[2] + d[4];
    t[1] = (d[3] + d[4]) - four * (d[1] + d[2]);
    t[2] = four * (d[1] - d[2]) + (d[4] - d[3]);
    t[3] = two * (d[3] - d[1]) + (d[4] - d[2]);
    t[4] = two * (d[1] - d[3]) + (d[4] - d[2]);
    t[5] = four * d[1] - five * d[3] + d[5];
}

// y = A^T m for one line of six vectors.
inline void outputLine(const Float8 (&m)[kPatch], Float8 (&y)[kRows]) {
    const Float8 two = Float8::broadcast(2.0f), four = Float8::broadcast(4.0f), eight = Float8::broadcast(8.0f);
    const Float8 sum12 = m[1] + m[2], diff12 = m[1] - m[2], sum34 = m[3] + m[4], diff34 = m[3] - m[4];
    y[0] = m[0] + sum12 + sum34;
    y[1] = diff12 + two * diff34;
    y[2] = sum12 + four * sum34;
    y[3] = diff12 + eight * diff34 + m[5];
}

// V = B^T d B for the `channels` channels of a 6x6 patch whose pixel (i, j) starts at
// rows[i] + j * pixelStride; position i * 6 + j of V goes to dst + (i * 6 + j) * plane.
// Eight channels at a time: each patch row across, then each column down.
void transformPatch(const float* const (&rows)[kPatch], std::size_t pixelStride, int channels, std::size_t plane,
                    float* dst) {
    for (int c = 0; c < channels; c += 8) {
        const int lanes = std::min(8, channels - c);
        Float8 across[kPatch][kPatch];  // [patch row][column of V]
        for (int i = 0; i < kPatch; ++i) {
            Float8 d[kPatch];
            for (int j = 0; j < kPatch; ++j) d[j] = loadLanes(rows[i] + std::size_t(j) * pixelStride + c, lanes);
            inputLine(d, across[i]);
        }
        for (int j = 0; j < kPatch; ++j) {
            Float8 column[kPatch], v[kPatch];
            for (int i = 0; i < kPatch; ++i) column[i] = across[i][j];
            inputLine(column, v);
            for (int i = 0; i < kPatch; ++i) storeLanes(v[i], dst + std::size_t(i * kPatch + j) * plane + c, lanes);
        }
    }
}

// Y = A^T M A + bias for the `channels` output channels of one tile; position (i, j) of M is at
// m + (i * 6 + j) * plane. Output pixel (r, q) goes to out[r][q]; with `add`, onto the value
// there (before the activation).
void transformOutput(const float* m, std::size_t plane, const float* bias, int channels, bool leaky, bool add,
                     float* const (&out)[kRows][kRows]) {
    const Float8 slope = Float8::broadcast(0.01f);  // leaky ReLU
    for (int o = 0; o < channels; o += 8) {
        const int lanes = std::min(8, channels - o);
        Float8 down[kRows][kPatch];  // [output row][column of M]
        for (int j = 0; j < kPatch; ++j) {
            Float8 column[kPatch], y[kRows];
            for (int i = 0; i < kPatch; ++i) column[i] = loadLanes(m + std::size_t(i * kPatch + j) * plane + o, lanes);
            outputLine(column, y);
            for (int r = 0; r < kRows; ++r) down[r][j] = y[r];
        }
        const Float8 b = loadLanes(bias + o, lanes);
        for (int r = 0; r < kRows; ++r) {
            Float8 y[kRows];
            outputLine(down[r], y);
            for (int q = 0; q < kRows; ++q) {
                Float8 value = y[q] + b;
                if (add) value = loadLanes(out[r][q] + o, lanes) + value;
                if (leaky) value = max(value, value * slope);
                storeLanes(value, out[r][q] + o, lanes);
            }
        }
    }
}

}  // namespace

WinogradConv::WinogradConv(const float* torchWeights, const float* bias, int outChannels, int inChannels,
                           ConvIsa isa)
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
}

void WinogradConv::strip(const ConvSource* sources, int sourceCount, int height, int width, int tileY, int x0,
                         int x1, Activation activation, bool add, float* const* rows) const {
    // Per thread, reused from call to call: the transformed input and products of kTilesPerTask
    // tiles, a border tile's patch, and where the outputs outside the rows and columns asked for go.
    thread_local AlignedVector<float> v, m;
    thread_local std::vector<float> patch, discard;
    const std::size_t inPlane = std::size_t(kTilesPerTask) * in_, outPlane = std::size_t(kTilesPerTask) * out_;
    if (v.size() < kPositions * inPlane) v.resize(kPositions * inPlane);
    if (m.size() < kPositions * outPlane) m.resize(kPositions * outPlane);
    if (patch.size() < kPositions * std::size_t(in_)) patch.resize(kPositions * std::size_t(in_));
    if (discard.size() < std::size_t(out_)) discard.resize(std::size_t(out_), 0.0f);
    const bool leaky = activation == Activation::LeakyRelu;
    const int endTile = (x1 + kRows - 1) / kRows;
    for (int firstTile = x0 / kRows; firstTile < endTile; firstTile += kTilesPerTask) {
        const int tiles = std::min(kTilesPerTask, endTile - firstTile);
        for (int t = 0; t < tiles; ++t) {
            float* dst = v.data() + std::size_t(t) * in_;
            for (int s = 0; s < sourceCount; ++s) {
                const float* patchRow[kPatch];
                const std::size_t stride = winograd::patchRows<kPatch>(
                    sources[s], height, width, kRows * tileY - 1, kRows * (firstTile + t) - 1, patch.data(), patchRow);
                transformPatch(patchRow, stride, sources[s].channels, inPlane, dst);
                dst += sources[s].channels;
            }
        }
        for (int p = 0; p < kPositions; ++p) {
            const ConvSource position{v.data() + std::size_t(p) * inPlane, in_};
            convolveRow(positions_[std::size_t(p)], &position, 1, 1, tiles, 0, 0, tiles, Activation::None,
                        m.data() + std::size_t(p) * outPlane);
        }
        for (int t = 0; t < tiles; ++t) {
            const int x = kRows * (firstTile + t);
            float* out[kRows][kRows];
            for (int r = 0; r < kRows; ++r)
                for (int q = 0; q < kRows; ++q) {
                    const bool wanted = rows[r] && x + q >= x0 && x + q < x1;
                    out[r][q] = wanted ? rows[r] + std::size_t(x + q) * out_ : discard.data();
                }
            transformOutput(m.data() + std::size_t(t) * out_, outPlane, bias_.data(), out_, leaky, add, out);
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
