#include "conv_kernel.h"

#include <algorithm>
#include <string>

#include "affinity/error.h"
#include "simd8.h"

namespace affinity {
namespace {

constexpr int kLanes = Float8::kLanes;
constexpr float kLeakySlope = 0.01f;

// Output pixels per register block for N vectors of output channels: M x N accumulators,
// N weight vectors and one broadcast input must fit in the 16 ymm registers.
template <int N>
constexpr int kBlockPixels = N == 2 ? 6 : 8;

// Everything a register block needs besides its position; one per (row, channel block).
struct BlockArgs {
    const ConvSource* sources;
    int sourceCount;
    int width;
    int y;
    int radius, size;
    int kyBegin, kyEnd, kxBegin, kxEnd;  // tap offsets that stay inside the image
    std::size_t tapStride;               // floats of weights per tap
    const float* weights;
    const float* bias;
    int outStride;   // output channels
    int tailLanes;   // valid lanes of the block's last vector
    bool leaky;
};

// acc[m] += sum over j < count of pixel[m][j] * w[j] for M pixels: the innermost loop,
// M x N FMAs per j, each operand in a register or one load away (base + index addressing).
template <int M, int N>
inline void accumulate(Float8 (&acc)[M][N], const float* const (&pixel)[M], int count, const float* w) {
#pragma GCC unroll 2
    for (int j = 0; j < count; ++j) {
        Float8 wv[N];
#pragma GCC unroll 16
        for (int n = 0; n < N; ++n) wv[n] = Float8::load(w + std::size_t(j) * (N * kLanes) + n * kLanes);
#pragma GCC unroll 16
        for (int m = 0; m < M; ++m) {
            const Float8 xv = Float8::broadcast(pixel[m] + j);
#pragma GCC unroll 16
            for (int n = 0; n < N; ++n) acc[m][n] = fma(xv, wv[n], acc[m][n]);
        }
    }
}

// The same for M pixels `stride` floats apart starting at `in`.
template <int M, int N>
inline void accumulate(Float8 (&acc)[M][N], const float* in, std::size_t stride, int count, const float* w) {
    const float* pixel[M];
#pragma GCC unroll 16
    for (int m = 0; m < M; ++m) pixel[m] = in + std::size_t(m) * stride;
    accumulate<M, N>(acc, pixel, count, w);
}

// M consecutive output pixels starting at column x, all of whose taps in [kxBegin, kxEnd]
// exist; out points at the first pixel's first channel of this block.
template <int M, int N>
void convBlock(const BlockArgs& a, int x, float* out) {
    Float8 acc[M][N];
#pragma GCC unroll 16
    for (int n = 0; n < N; ++n) {
        const Float8 b = Float8::load(a.bias + n * kLanes);
#pragma GCC unroll 16
        for (int m = 0; m < M; ++m) acc[m][n] = b;
    }
    const int r = a.radius;
    if (a.sourceCount == 1 && !a.sources[0].upsampled && a.kxBegin == -r && a.kxEnd == r) {
        // One source and a full row of taps: for a given ky the (kx, channel) pairs are
        // contiguous in both the input row and the packed weights, so the taps of a row run
        // as one loop. Same accumulation order as tap by tap.
        const int channels = a.sources[0].channels;
        for (int ky = a.kyBegin; ky <= a.kyEnd; ++ky) {
            const float* w = a.weights + std::size_t((ky + r) * a.size) * a.tapStride;
            const float* in = a.sources[0].data + (std::size_t(a.y + ky) * a.width + std::size_t(x - r)) * channels;
            accumulate<M, N>(acc, in, std::size_t(channels), a.size * channels, w);
        }
    } else {
        for (int ky = a.kyBegin; ky <= a.kyEnd; ++ky) {
            for (int kx = a.kxBegin; kx <= a.kxEnd; ++kx) {
                const float* w = a.weights + std::size_t((ky + r) * a.size + kx + r) * a.tapStride;
                for (int s = 0; s < a.sourceCount; ++s) {
                    const ConvSource& source = a.sources[s];
                    const int channels = source.channels;
                    if (source.upsampled) {
                        const std::size_t sourceWidth = std::size_t(a.width + 1) / 2;
                        const float* row = source.data + std::size_t((a.y + ky) / 2) * sourceWidth * channels;
                        const float* pixel[M];
#pragma GCC unroll 16
                        for (int m = 0; m < M; ++m) pixel[m] = row + std::size_t((x + m + kx) / 2) * channels;
                        accumulate<M, N>(acc, pixel, channels, w);
                    } else {
                        const float* in =
                            source.data + (std::size_t(a.y + ky) * a.width + std::size_t(x + kx)) * channels;
                        accumulate<M, N>(acc, in, std::size_t(channels), channels, w);
                    }
                    w += std::size_t(channels) * (N * kLanes);
                }
            }
        }
    }
    const Float8 slope = Float8::broadcast(kLeakySlope);
#pragma GCC unroll 16
    for (int m = 0; m < M; ++m) {
        float* o = out + std::size_t(m) * a.outStride;
#pragma GCC unroll 16
        for (int n = 0; n < N; ++n) {
            Float8 v = acc[m][n];
            if (a.leaky) v = max(v, v * slope);
            if (n == N - 1 && a.tailLanes < kLanes)
                v.storePartial(o + n * kLanes, a.tailLanes);
            else
                v.storeu(o + n * kLanes);
        }
    }
}

// A block of `count` (< M) pixels: the end of an interior run.
template <int N, int M>
void convTail(const BlockArgs& a, int x, int count, float* out) {
    if constexpr (M > 0) {
        if (count == M)
            convBlock<M, N>(a, x, out);
        else
            convTail<N, M - 1>(a, x, count, out);
    }
}

// Columns [x0, x1) of one channel block. Pixels within `radius` of the left or right border
// go one at a time with their missing taps skipped (a zero-padded tap adds 0 * w, which
// changes no sum for finite weights); the rest in blocks of M.
template <int N>
void convolveRange(BlockArgs a, int x0, int x1, float* outRow) {
    constexpr int M = kBlockPixels<N>;
    const int r = a.radius;
    int x = x0;
    while (x < x1) {
        if (x < r || x >= a.width - r) {
            BlockArgs edge = a;
            edge.kxBegin = std::max(-r, -x);
            edge.kxEnd = std::min(r, a.width - 1 - x);
            convBlock<1, N>(edge, x, outRow + std::size_t(x) * a.outStride);
            ++x;
            continue;
        }
        const int end = std::min(x1, a.width - r);
        a.kxBegin = -r;
        a.kxEnd = r;
        for (; x + M <= end; x += M) convBlock<M, N>(a, x, outRow + std::size_t(x) * a.outStride);
        if (x < end) convTail<N, M - 1>(a, x, end - x, outRow + std::size_t(x) * a.outStride);
        x = end;
    }
}

}  // namespace

PackedConv::PackedConv(const float* torchWeights, const float* bias, int outChannels, int inChannels, int size)
    : out_(outChannels), in_(inChannels), size_(size) {
    if (outChannels <= 0 || inChannels <= 0 || (size != 1 && size != 3))
        throw Error("convolution: unsupported shape [" + std::to_string(outChannels) + ", " +
                    std::to_string(inChannels) + ", " + std::to_string(size) + ", " + std::to_string(size) + "]");
    const int taps = size * size;
    const int vectors = (outChannels + kLanes - 1) / kLanes;
    weights_.assign(std::size_t(taps) * inChannels * vectors * kLanes, 0.0f);
    bias_.assign(std::size_t(vectors) * kLanes, 0.0f);
    if (bias)
        for (int o = 0; o < outChannels; ++o) bias_[o] = bias[o];

    std::size_t offset = 0;
    for (int v = 0; v < vectors;) {
        const int blockVectors = vectors - v >= 2 ? 2 : 1;
        const int lanes = blockVectors * kLanes;
        const Block block{v * kLanes, blockVectors, offset};
        for (int tap = 0; tap < taps; ++tap) {
            for (int c = 0; c < inChannels; ++c) {
                float* dst = weights_.data() + offset + (std::size_t(tap) * inChannels + c) * lanes;
                for (int l = 0; l < lanes; ++l) {
                    const int o = block.firstChannel + l;
                    if (o < outChannels) dst[l] = torchWeights[(std::size_t(o) * inChannels + c) * taps + tap];
                }
            }
        }
        blocks_.push_back(block);
        offset += std::size_t(taps) * inChannels * lanes;
        v += blockVectors;
    }
}

void convolveRow(const PackedConv& conv, const ConvSource* sources, int sourceCount, int height, int width, int y,
                 int x0, int x1, Activation activation, float* outputRow) {
    const int r = conv.size() / 2;
    BlockArgs a{};
    a.sources = sources;
    a.sourceCount = sourceCount;
    a.width = width;
    a.y = y;
    a.radius = r;
    a.size = conv.size();
    a.kyBegin = std::max(-r, -y);
    a.kyEnd = std::min(r, height - 1 - y);
    a.outStride = conv.outChannels();
    a.leaky = activation == Activation::LeakyRelu;
    for (const PackedConv::Block& block : conv.blocks()) {
        a.weights = conv.weights() + block.offset;
        a.bias = conv.bias() + block.firstChannel;
        a.tapStride = std::size_t(conv.inChannels()) * block.vectors * kLanes;
        a.tailLanes = std::min(kLanes, conv.outChannels() - block.firstChannel - (block.vectors - 1) * kLanes);
        float* out = outputRow + block.firstChannel;
        if (block.vectors == 2)
            convolveRange<2>(a, x0, x1, out);
        else
            convolveRange<1>(a, x0, x1, out);
    }
}

}  // namespace affinity
