// The bfloat16 products of bf16_gemm.h: VDPBF16PS, register-blocked like conv_blocks.h (12 rows
// x up to two 16-lane vectors of output channels; a last vector with at most 8 channels runs
// on 256-bit registers, half the uops on cores that split 512-bit operations). Built with
// -march=x86-64-v4 -mavx512bf16 and entered only after cpuHasAvx512Bf16(). The Winograd patch
// transforms that store V in bfloat16 are instantiated here too, where the conversion compiles.
#include <immintrin.h>

#include "kernels/bf16_gemm.h"
#include "kernels/coarse_winograd_transforms.h"
#include "kernels/simd16.h"
#include "kernels/winograd_transforms.h"

namespace affinity {
namespace {

namespace winograd_lines {
template <>
void storeLanes<Float16>(Float16 v, std::uint16_t* p, int count) {
    const __m256i rounded = (__m256i)_mm512_cvtneps_pbh(v.v);
    if (count == Float16::kLanes)
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(p), rounded);
    else
        _mm256_mask_storeu_epi16(p, __mmask16((1u << count) - 1u), rounded);
}
}  // namespace winograd_lines

constexpr int kLanes = 16;
constexpr int kBlockRows = 12;

// Everything a block needs besides its rows.
struct BlockArgs {
    std::size_t xStride;  // in 32-bit words
    int pairs;
    const std::uint32_t* w;
    const float* bias;  // the block's first channel, padded to its lanes
    std::size_t outStride;
    int tailLanes;
    bool leaky;
};

template <int M, int N, bool HalfTail>
void gemmBlock(const BlockArgs& a, const std::uint32_t* x, float* out) {
    constexpr int Full = HalfTail ? N - 1 : N;
    const std::size_t xStride = a.xStride;
    const std::uint32_t* w = a.w;
    __m512 acc[M][N];
    __m256 tail[M];
    __m512 bias[N];
#pragma GCC unroll 2
    for (int n = 0; n < Full; ++n) bias[n] = _mm512_loadu_ps(a.bias + n * kLanes);
    const __m256 tailBias = HalfTail ? _mm256_loadu_ps(a.bias + Full * kLanes) : _mm256_setzero_ps();
#pragma GCC unroll 16
    for (int m = 0; m < M; ++m) {
#pragma GCC unroll 2
        for (int n = 0; n < Full; ++n) acc[m][n] = bias[n];
        tail[m] = tailBias;
    }
#pragma GCC unroll 2
    for (int k = 0; k < a.pairs; ++k) {
        const std::uint32_t* wk = w + std::size_t(k) * (N * kLanes);
        __m512i wv[N];
#pragma GCC unroll 2
        for (int n = 0; n < Full; ++n) wv[n] = _mm512_load_si512(wk + n * kLanes);
        __m256i wt = _mm256_setzero_si256();
        if constexpr (HalfTail) wt = _mm256_load_si256(reinterpret_cast<const __m256i*>(wk + Full * kLanes));
#pragma GCC unroll 16
        for (int m = 0; m < M; ++m) {
            // One pair of the row's bfloat16 inputs in every lane.
            const __m512i xb = _mm512_set1_epi32(int(x[std::size_t(m) * xStride + k]));
#pragma GCC unroll 2
            for (int n = 0; n < Full; ++n) acc[m][n] = _mm512_dpbf16_ps(acc[m][n], (__m512bh)xb, (__m512bh)wv[n]);
            if constexpr (HalfTail) {
                // The low half as a 256-bit value (a shuffle: GCC 12's cast intrinsic trips
                // -Wmaybe-uninitialized).
                const __m256i low = (__m256i)__builtin_shufflevector((__v16si)xb, (__v16si)xb, 0, 1, 2, 3, 4, 5, 6, 7);
                tail[m] = _mm256_dpbf16_ps(tail[m], (__m256bh)low, (__m256bh)wt);
            }
        }
    }
    const Float16 slope = Float16::broadcast(0.01f);  // leaky ReLU
#pragma GCC unroll 16
    for (int m = 0; m < M; ++m) {
        float* o = out + std::size_t(m) * a.outStride;
#pragma GCC unroll 2
        for (int n = 0; n < Full; ++n) {
            Float16 v{acc[m][n]};
            if (a.leaky) v = max(v, v * slope);
            if (n == N - 1 && a.tailLanes < kLanes)
                v.storePartial(o + n * kLanes, a.tailLanes);
            else
                v.storeu(o + n * kLanes);
        }
        if constexpr (HalfTail) {
            __m256 v = tail[m];
            if (a.leaky) v = _mm256_max_ps(v, _mm256_mul_ps(v, _mm256_set1_ps(0.01f)));
            _mm256_mask_storeu_ps(o + Full * kLanes, __mmask8((1u << a.tailLanes) - 1u), v);
        }
    }
}

// The last rows % kBlockRows rows.
template <int N, bool HalfTail, int M = kBlockRows - 1>
void gemmRest(const BlockArgs& a, const std::uint32_t* x, int rows, float* out) {
    if constexpr (M > 0) {
        if (rows == M)
            gemmBlock<M, N, HalfTail>(a, x, out);
        else
            gemmRest<N, HalfTail, M - 1>(a, x, rows, out);
    }
}

template <int N, bool HalfTail>
void gemmColumns(const BlockArgs& a, const std::uint32_t* x, int rows, float* out) {
    int r = 0;
    for (; r + kBlockRows <= rows; r += kBlockRows)
        gemmBlock<kBlockRows, N, HalfTail>(a, x + std::size_t(r) * a.xStride, out + std::size_t(r) * a.outStride);
    if (r < rows)
        gemmRest<N, HalfTail>(a, x + std::size_t(r) * a.xStride, rows - r, out + std::size_t(r) * a.outStride);
}

}  // namespace

void gemmBf16Avx512(const PackedGemmBf16& w, const std::uint16_t* x, std::size_t xStride, int rows, float* out,
                    std::size_t outStride, bool leaky) {
    const auto* words = reinterpret_cast<const std::uint32_t*>(x);
    for (const PackedGemmBf16::Block& block : w.blocks()) {
        const int tailLanes = w.outChannels() - block.firstChannel - (block.vectors - 1) * kLanes;
        const BlockArgs a{xStride / 2,
                          w.inChannels() / 2,
                          w.words() + block.offset,
                          w.bias() + block.firstChannel,
                          outStride,
                          tailLanes < kLanes ? tailLanes : kLanes,
                          leaky};
        float* o = out + block.firstChannel;
        if (block.vectors == 2)
            a.tailLanes <= 8 ? gemmColumns<2, true>(a, words, rows, o) : gemmColumns<2, false>(a, words, rows, o);
        else
            a.tailLanes <= 8 ? gemmColumns<1, true>(a, words, rows, o) : gemmColumns<1, false>(a, words, rows, o);
    }
}

WinogradPatchTransformBf16 winogradPatchTransformBf16() {
    return winograd_lines::transformPatch<Float16, std::uint16_t>;
}

CoarsePatchTransformBf16 coarsePatchTransformBf16() { return coarse_lines::transformPatch<Float16, std::uint16_t>; }

void convertToBf16Avx512(const float* src, std::size_t count, std::uint16_t* dst) {
    std::size_t i = 0;
    for (; i + 16 <= count; i += 16)
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(dst + i), (__m256i)_mm512_cvtneps_pbh(_mm512_loadu_ps(src + i)));
    if (i < count) {
        const __mmask16 mask = __mmask16((1u << (count - i)) - 1u);
        const __m256i v = (__m256i)_mm512_cvtneps_pbh(_mm512_maskz_loadu_ps(mask, src + i));
        _mm256_mask_storeu_epi16(dst + i, mask, v);
    }
}

}  // namespace affinity
