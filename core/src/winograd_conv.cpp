#include "winograd_conv.h"

#include <algorithm>
#include <string>

#include "affinity/error.h"
#include "aligned_allocator.h"
#include "simd8.h"

namespace affinity {
namespace {

// Tiles (2x2 output pixels) transformed at a time: 48 output columns. Their transformed input
// (16 x 24 x inChannels floats, 96 KiB at 64 channels) stays in L2 while each position's 1x1
// convolution streams through it; 24 is a whole number of the kernel's register blocks (12, 8
// and 6 pixels). 12, 24 and 48 were within this VM's noise of each other in bench_conv.
constexpr int kTilesPerTask = 24;

// Lanes [0, count) of p, count in 1..8 (the rest read as 0).
Float8 loadLanes(const float* p, int count) { return count == 8 ? Float8::loadu(p) : Float8::loadPartial(p, count); }
void storeLanes(Float8 v, float* p, int count) {
    if (count == 8)
        v.storeu(p);
    else
        v.storePartial(p, count);
}

// V = B^T d B for the `channels` channels of a 4x4 patch whose pixel (i, j) starts at
// rows[i] + j * pixelStride; position i * 4 + j of V goes to dst + (i * 4 + j) * plane.
// Eight channels at a time with four row pointers, so nothing spills from the registers.
void transformPatch(const float* const (&rows)[4], std::size_t pixelStride, int channels, std::size_t plane,
                    float* dst) {
    for (int c = 0; c < channels; c += 8) {
        const int lanes = std::min(8, channels - c);
        // B^T = [1 0 -1 0; 0 1 1 0; 0 -1 1 0; 0 1 0 -1] on each row's four pixels, then on the rows.
        Float8 t[4][4];
        for (int i = 0; i < 4; ++i) {
            const float* row = rows[i] + c;
            const Float8 d0 = loadLanes(row, lanes), d1 = loadLanes(row + pixelStride, lanes);
            const Float8 d2 = loadLanes(row + 2 * pixelStride, lanes), d3 = loadLanes(row + 3 * pixelStride, lanes);
            t[i][0] = d0 - d2;
            t[i][1] = d1 + d2;
            t[i][2] = d2 - d1;
            t[i][3] = d1 - d3;
        }
        float* out = dst + c;
        for (int j = 0; j < 4; ++j) {
            storeLanes(t[0][j] - t[2][j], out + std::size_t(j) * plane, lanes);
            storeLanes(t[1][j] + t[2][j], out + std::size_t(4 + j) * plane, lanes);
            storeLanes(t[2][j] - t[1][j], out + std::size_t(8 + j) * plane, lanes);
            storeLanes(t[1][j] - t[3][j], out + std::size_t(12 + j) * plane, lanes);
        }
    }
}

// Y = A^T M A + bias for the `channels` output channels of one tile, A^T = [1 1 1 0; 0 1 -1 -1];
// position (i, j) of M is at m + (i * 4 + j) * plane. Output pixel (r, q) goes to out[r][q].
// With `add`, onto the values already at out[r][q] (before the activation).
void transformOutput(const float* m, std::size_t plane, const float* bias, int channels, bool leaky, bool add,
                     float* const (&out)[2][2]) {
    const Float8 slope = Float8::broadcast(0.01f);  // leaky ReLU
    for (int o = 0; o < channels; o += 8) {
        const int lanes = std::min(8, channels - o);
        Float8 s[2][4];
        for (int j = 0; j < 4; ++j) {
            const float* p = m + o + std::size_t(j) * plane;
            const Float8 m0 = loadLanes(p, lanes), m1 = loadLanes(p + 4 * plane, lanes);
            const Float8 m2 = loadLanes(p + 8 * plane, lanes), m3 = loadLanes(p + 12 * plane, lanes);
            s[0][j] = m0 + m1 + m2;
            s[1][j] = m1 - m2 - m3;
        }
        const Float8 b = loadLanes(bias + o, lanes);
        for (int r = 0; r < 2; ++r) {
            Float8 y[2] = {s[r][0] + s[r][1] + s[r][2] + b, s[r][1] - s[r][2] - s[r][3] + b};
            for (int q = 0; q < 2; ++q) {
                if (add) y[q] = loadLanes(out[r][q] + o, lanes) + y[q];
                if (leaky) y[q] = max(y[q], y[q] * slope);
                storeLanes(y[q], out[r][q] + o, lanes);
            }
        }
    }
}

// The 4x4 input patch of the tile whose top-left output pixel is (2 * tileY, 2 * tileX), for
// transformPatch: straight from the image where the patch lies inside it, else copied into
// `patch` (16 x channels floats) with zeros for the padding and the upsampling resolved.
std::size_t patchRows(const ConvSource& source, int height, int width, int tileY, int tileX, float* patch,
                      const float* (&rows)[4]) {
    const int y0 = 2 * tileY - 1, x0 = 2 * tileX - 1;
    const std::size_t channels = std::size_t(source.channels);
    if (!source.upsampled && y0 >= 0 && y0 + 3 < height && x0 >= 0 && x0 + 3 < width) {
        for (int i = 0; i < 4; ++i) rows[i] = source.data + (std::size_t(y0 + i) * width + std::size_t(x0)) * channels;
        return channels;
    }
    const std::size_t sourceWidth = source.upsampled ? std::size_t(width + 1) / 2 : std::size_t(width);
    for (int i = 0; i < 4; ++i) {
        rows[i] = patch + std::size_t(i) * 4 * channels;
        for (int j = 0; j < 4; ++j) {
            float* dst = patch + std::size_t(i * 4 + j) * channels;
            const int y = y0 + i, x = x0 + j;
            if (y < 0 || y >= height || x < 0 || x >= width) {
                std::fill(dst, dst + channels, 0.0f);
                continue;
            }
            const int sy = source.upsampled ? y / 2 : y, sx = source.upsampled ? x / 2 : x;
            const float* pixel = source.data + (std::size_t(sy) * sourceWidth + std::size_t(sx)) * channels;
            std::copy(pixel, pixel + channels, dst);
        }
    }
    return channels;
}

}  // namespace

WinogradConv::WinogradConv(const float* torchWeights, const float* bias, int outChannels, int inChannels,
                           ConvIsa isa)
    : out_(outChannels), in_(inChannels), bias_(std::size_t(std::max(outChannels, 0)), 0.0f) {
    if (outChannels <= 0 || inChannels <= 0)
        throw Error("Winograd convolution: unsupported shape [" + std::to_string(outChannels) + ", " +
                    std::to_string(inChannels) + ", 3, 3]");
    if (bias) std::copy(bias, bias + outChannels, bias_.begin());
    // U = G g G^T per (output, input) channel, G = [1 0 0; 1/2 1/2 1/2; 1/2 -1/2 1/2; 0 0 1],
    // in double and rounded once; stored per position in torch's 1x1 layout [out][in].
    const double G[4][3] = {{1, 0, 0}, {0.5, 0.5, 0.5}, {0.5, -0.5, 0.5}, {0, 0, 1}};
    std::vector<std::vector<float>> u(16, std::vector<float>(std::size_t(outChannels) * inChannels));
    for (int o = 0; o < outChannels; ++o)
        for (int c = 0; c < inChannels; ++c) {
            const float* g = torchWeights + (std::size_t(o) * inChannels + c) * 9;
            for (int i = 0; i < 4; ++i)
                for (int j = 0; j < 4; ++j) {
                    double sum = 0.0;
                    for (int a = 0; a < 3; ++a)
                        for (int b = 0; b < 3; ++b) sum += G[i][a] * double(g[a * 3 + b]) * G[j][b];
                    u[std::size_t(i * 4 + j)][std::size_t(o) * inChannels + c] = float(sum);
                }
        }
    for (int p = 0; p < 16; ++p) positions_[std::size_t(p)] = PackedConv(u[std::size_t(p)].data(), nullptr,
                                                                            outChannels, inChannels, 1, isa);
}

void WinogradConv::strip(const ConvSource* sources, int sourceCount, int height, int width, int tileY, int x0,
                         int x1, Activation activation, bool add, float* const (&rows)[2]) const {
    // Per thread, reused from call to call: the transformed input and products of kTilesPerTask
    // tiles, a border tile's patch, and where the outputs past the image go.
    thread_local AlignedVector<float> v, m;
    thread_local std::vector<float> patch, discard;
    const std::size_t inPlane = std::size_t(kTilesPerTask) * in_, outPlane = std::size_t(kTilesPerTask) * out_;
    if (v.size() < 16 * inPlane) v.resize(16 * inPlane);
    if (m.size() < 16 * outPlane) m.resize(16 * outPlane);
    if (patch.size() < 16 * std::size_t(in_)) patch.resize(16 * std::size_t(in_));
    if (discard.size() < std::size_t(out_)) discard.resize(std::size_t(out_), 0.0f);
    const bool leaky = activation == Activation::LeakyRelu;
    const int lastTile = (x1 + 1) / 2;  // one past
    for (int firstTile = x0 / 2; firstTile < lastTile; firstTile += kTilesPerTask) {
        const int tiles = std::min(kTilesPerTask, lastTile - firstTile);
        for (int t = 0; t < tiles; ++t) {
            float* dst = v.data() + std::size_t(t) * in_;
            for (int s = 0; s < sourceCount; ++s) {
                const float* patchRow[4];
                const std::size_t stride =
                    patchRows(sources[s], height, width, tileY, firstTile + t, patch.data(), patchRow);
                transformPatch(patchRow, stride, sources[s].channels, inPlane, dst);
                dst += sources[s].channels;
            }
        }
        for (int p = 0; p < 16; ++p) {
            const ConvSource position{v.data() + std::size_t(p) * inPlane, in_};
            convolveRow(positions_[std::size_t(p)], &position, 1, 1, tiles, 0, 0, tiles, Activation::None,
                        m.data() + std::size_t(p) * outPlane);
        }
        for (int t = 0; t < tiles; ++t) {
            const int x = 2 * (firstTile + t);
            float* out[2][2];
            for (int r = 0; r < 2; ++r)
                for (int q = 0; q < 2; ++q)
                    out[r][q] = rows[r] && x + q >= x0 && x + q < x1 ? rows[r] + std::size_t(x + q) * out_ : discard.data();
            transformOutput(m.data() + std::size_t(t) * out_, outPlane, bias_.data(), out_, leaky, add, out);
        }
    }
}

void WinogradConv::apply(const ConvSource* sources, int sourceCount, int height, int width, Activation activation,
                         FeatureMap& output, bool parallel) const {
    const int tileRows = (height + 1) / 2, tileColumns = (width + 1) / 2;
    const int chunks = (tileColumns + kTilesPerTask - 1) / kTilesPerTask;
    const long long tasks = (long long)tileRows * chunks;
#pragma omp parallel for schedule(dynamic) if (parallel)
    for (long long task = 0; task < tasks; ++task) {
        const int tileY = int(task / chunks);
        const int x0 = int(task % chunks) * 2 * kTilesPerTask;
        const int x1 = std::min(width, x0 + 2 * kTilesPerTask);
        float* const rows[2] = {output.pixel(2 * tileY, 0),
                                2 * tileY + 1 < height ? output.pixel(2 * tileY + 1, 0) : nullptr};
        strip(sources, sourceCount, height, width, tileY, x0, x1, activation, false, rows);
    }
}

}  // namespace affinity
