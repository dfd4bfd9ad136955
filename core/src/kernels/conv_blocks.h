#pragma once
// The register-blocked inner loops of the convolution kernel (conv_kernel.h), written once
// over the vector type: Float8 (AVX2, conv_kernel.cpp) and Float16 (AVX-512,
// conv_kernel_avx512.cpp) instantiate them. Vectorised over output channels, so every output
// value is accumulated in the same order (bias, taps row-major, input channels in
// concatenation order) whatever the vector width: the two paths agree bitwise.
#include <cstddef>

#include "kernels/conv_kernel.h"

namespace affinity {

// Everything a register block needs besides its position; one per (row, channel block).
struct ConvBlockArgs {
    const ConvSource* sources;
    int sourceCount;
    int width;
    int y;
    int size;
    int originY, originX;                // offset of the first tap: -size / 2, or 2x2 phases' -1 or 0
    int kyBegin, kyEnd, kxBegin, kxEnd;  // tap offsets that stay inside the image
    std::size_t tapStride;               // floats of weights per tap
    const float* weights;
    const float* bias;
    int outStride;  // floats from one output pixel to the next
    int tailLanes;  // valid lanes of the block's last vector
    bool leaky;
    bool addToOutput;  // start from the output's values instead of the bias
};

#if AFFINITY_HAVE_AVX512_KERNEL
// Columns [x0, x1) of one block of `vectors` (1 or 2) 16-lane vectors of output channels
// (conv_kernel_avx512.cpp; call only where cpuHasAvx512()).
void convolveRangeAvx512(const ConvBlockArgs& a, int vectors, int x0, int x1, float* outRow);
#endif

// Internal linkage: each instruction set's translation unit keeps its own copies (an AVX-512
// copy must never be the one the linker keeps for the AVX2 path).
namespace {

// Output pixels per register block for N vectors of output channels: M x N accumulators,
// N weight vectors and one broadcast input must fit in the register file (16 ymm for AVX2,
// 32 zmm for AVX-512).
template <class V, int N>
constexpr int kBlockPixels = V::kLanes == 16 ? 12 : (N == 2 ? 6 : 8);

// The type of a block's last accumulators: V, or V::Half (256 bits) with HalfTail.
template <class V, bool HalfTail>
struct TailVector {
    using type = V;
};
template <class V>
struct TailVector<V, true> {
    using type = typename V::Half;
};

// acc[m] += sum over j < count of pixel[m][j] * w[j] for M pixels: the innermost loop,
// M x N FMAs per j, each operand in a register or one load away (base + index addressing).
// With HalfTail (16-lane vectors only) the last vector's lanes 8-15 are idle and its
// products run at half width (lanes 0-7 computed exactly as at full width, the rest 0): on
// cores that split a 512-bit FMA in two (Zen 4) a 24-channel block then costs three 256-bit
// FMAs per pixel instead of four. Those accumulators live in 256-bit registers for the whole
// loop: kept as 512-bit values, each FMA needed a move to re-zero lanes 8-15, an extra uop on
// the FMA ports of cores with full-width units (on Intel, 24-channel blocks fell behind AVX2).
template <class V, int M, int N, bool HalfTail>
inline void accumulate(V (&acc)[M][N], const float* const (&pixel)[M], int count, const float* w) {
    using Tail = typename TailVector<V, HalfTail>::type;
    constexpr int L = V::kLanes;
    constexpr int Full = HalfTail ? N - 1 : N;  // vectors at full width
    [[maybe_unused]] Tail tail[HalfTail ? M : 1];
    if constexpr (HalfTail) {
#pragma GCC unroll 16
        for (int m = 0; m < M; ++m) tail[m] = acc[m][N - 1].low();
    }
#pragma GCC unroll 2
    for (int j = 0; j < count; ++j) {
        const float* wj = w + std::size_t(j) * (N * L);
        V wv[N];
#pragma GCC unroll 16
        for (int n = 0; n < Full; ++n) wv[n] = V::load(wj + n * L);
        [[maybe_unused]] Tail wt{};
        if constexpr (HalfTail) wt = V::loadHalf(wj + Full * L);
#pragma GCC unroll 16
        for (int m = 0; m < M; ++m) {
            const V xv = V::broadcast(pixel[m] + j);
#pragma GCC unroll 16
            for (int n = 0; n < Full; ++n) acc[m][n] = fma(xv, wv[n], acc[m][n]);
            if constexpr (HalfTail) tail[m] = V::fmaHalf(xv.low(), wt, tail[m]);
        }
    }
    if constexpr (HalfTail) {
#pragma GCC unroll 16
        for (int m = 0; m < M; ++m) acc[m][N - 1] = V::widen(tail[m]);
    }
}

// The same for M pixels `stride` floats apart starting at `in`.
template <class V, int M, int N, bool HalfTail>
inline void accumulate(V (&acc)[M][N], const float* in, std::size_t stride, int count, const float* w) {
    const float* pixel[M];
#pragma GCC unroll 16
    for (int m = 0; m < M; ++m) pixel[m] = in + std::size_t(m) * stride;
    accumulate<V, M, N, HalfTail>(acc, pixel, count, w);
}

// M consecutive output pixels starting at column x, all of whose taps in [kxBegin, kxEnd]
// exist; out points at the first pixel's first channel of this block.
template <class V, int M, int N, bool HalfTail = false>
void convBlock(const ConvBlockArgs& a, int x, float* out) {
    constexpr int L = V::kLanes;
    V acc[M][N];
    if (a.addToOutput) {
#pragma GCC unroll 16
        for (int m = 0; m < M; ++m)
#pragma GCC unroll 16
            for (int n = 0; n < N; ++n)
                acc[m][n] = V::loadPartial(out + std::size_t(m) * a.outStride + n * L, n == N - 1 ? a.tailLanes : L);
    } else {
#pragma GCC unroll 16
        for (int n = 0; n < N; ++n) {
            const V b = V::load(a.bias + n * L);
#pragma GCC unroll 16
            for (int m = 0; m < M; ++m) acc[m][n] = b;
        }
    }
    const int lastTap = a.originX + a.size - 1;
    if (a.sourceCount == 1 && !a.sources[0].upsampled && a.kxBegin == a.originX && a.kxEnd == lastTap) {
        // One source and a full row of taps: for a given ky the (kx, channel) pairs are
        // contiguous in both the input row and the packed weights, so the taps of a row run
        // as one loop. Same accumulation order as tap by tap.
        const int channels = a.sources[0].channels;
        for (int ky = a.kyBegin; ky <= a.kyEnd; ++ky) {
            const float* w = a.weights + std::size_t((ky - a.originY) * a.size) * a.tapStride;
            const float* in =
                a.sources[0].data + (std::size_t(a.y + ky) * a.width + std::size_t(x + a.originX)) * channels;
            accumulate<V, M, N, HalfTail>(acc, in, std::size_t(channels), a.size * channels, w);
        }
    } else {
        for (int ky = a.kyBegin; ky <= a.kyEnd; ++ky) {
            for (int kx = a.kxBegin; kx <= a.kxEnd; ++kx) {
                const float* w = a.weights + std::size_t((ky - a.originY) * a.size + kx - a.originX) * a.tapStride;
                for (int s = 0; s < a.sourceCount; ++s) {
                    const ConvSource& source = a.sources[s];
                    const int channels = source.channels;
                    if (source.upsampled) {
                        const std::size_t sourceWidth = std::size_t(a.width + 1) / 2;
                        const float* row = source.data + std::size_t((a.y + ky) / 2) * sourceWidth * channels;
                        const float* pixel[M];
#pragma GCC unroll 16
                        for (int m = 0; m < M; ++m) pixel[m] = row + std::size_t((x + m + kx) / 2) * channels;
                        accumulate<V, M, N, HalfTail>(acc, pixel, channels, w);
                    } else {
                        const float* in =
                            source.data + (std::size_t(a.y + ky) * a.width + std::size_t(x + kx)) * channels;
                        accumulate<V, M, N, HalfTail>(acc, in, std::size_t(channels), channels, w);
                    }
                    w += std::size_t(channels) * (N * L);
                }
            }
        }
    }
    const V slope = V::broadcast(0.01f);  // leaky ReLU
#pragma GCC unroll 16
    for (int m = 0; m < M; ++m) {
        float* o = out + std::size_t(m) * a.outStride;
#pragma GCC unroll 16
        for (int n = 0; n < N; ++n) {
            V v = acc[m][n];
            if (a.leaky) v = max(v, v * slope);
            if (n == N - 1 && a.tailLanes < L)
                v.storePartial(o + n * L, a.tailLanes);
            else
                v.storeu(o + n * L);
        }
    }
}

// A block of `count` (< M) pixels: the end of an interior run.
template <class V, int N, int M, bool HalfTail>
void convTail(const ConvBlockArgs& a, int x, int count, float* out) {
    if constexpr (M > 0) {
        if (count == M)
            convBlock<V, M, N, HalfTail>(a, x, out);
        else
            convTail<V, N, M - 1, HalfTail>(a, x, count, out);
    }
}

// Columns [x0, x1) of one channel block. Pixels whose taps reach past the left or right
// border go one at a time with their missing taps skipped (a zero-padded tap adds 0 * w,
// which changes no sum for finite weights); the rest in blocks of M. HalfTail: see accumulate().
template <class V, int N, bool HalfTail = false>
void convolveRange(ConvBlockArgs a, int x0, int x1, float* outRow) {
    constexpr int M = kBlockPixels<V, N>;
    const int first = a.originX, last = a.originX + a.size - 1;  // tap offsets
    const int interiorBegin = -first, interiorEnd = a.width - last;
    int x = x0;
    while (x < x1) {
        if (x < interiorBegin || x >= interiorEnd) {
            ConvBlockArgs edge = a;
            edge.kxBegin = -x > first ? -x : first;
            edge.kxEnd = a.width - 1 - x < last ? a.width - 1 - x : last;
            convBlock<V, 1, N, HalfTail>(edge, x, outRow + std::size_t(x) * a.outStride);
            ++x;
            continue;
        }
        const int end = x1 < interiorEnd ? x1 : interiorEnd;
        a.kxBegin = first;
        a.kxEnd = last;
        for (; x + M <= end; x += M) convBlock<V, M, N, HalfTail>(a, x, outRow + std::size_t(x) * a.outStride);
        if (x < end) convTail<V, N, M - 1, HalfTail>(a, x, end - x, outRow + std::size_t(x) * a.outStride);
        x = end;
    }
}

}  // namespace
}  // namespace affinity
