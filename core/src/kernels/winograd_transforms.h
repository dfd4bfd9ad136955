#pragma once
// The transforms of the Winograd form F(4x4, 3x3) (winograd_conv.h) written once over the
// vector type: Float8 (winograd_conv.cpp) and Float16 (winograd_conv_avx512.cpp) instantiate
// them. Vectorised over channels; every lane goes through the same operations with explicit
// fused multiply-adds, and both files are compiled without automatic contraction
// (core/CMakeLists.txt), so the two widths give the same bits. Sixteen lanes halve the
// instruction count, which pays even where the 512-bit operations are split in two (Zen 4's
// input transform ran faster with them).
#include <algorithm>
#include <cstddef>
#include <cstdint>

namespace affinity {

// Output pixels per tile side, input pixels per patch side.
inline constexpr int kWinogradRows = 4;
inline constexpr int kWinogradPatch = kWinogradRows + 2;

// V = B^T d B for the `channels` channels of a 6x6 patch whose pixel (i, j) starts at
// rows[i] + j * pixelStride; position i * 6 + j of V goes to dst + (i * 6 + j) * plane.
using WinogradPatchTransform = void (*)(const float* const (&rows)[kWinogradPatch], std::size_t pixelStride,
                                        int channels, std::size_t plane, float* dst);
// Y = A^T M A + bias for the `channels` output channels of one tile; position (i, j) of M is at
// m + (i * 6 + j) * plane. Output pixel (r, q) goes to out[r][q]; with `add`, onto the value
// there (before the activation); `leaky`: leaky ReLU (slope 0.01).
using WinogradOutputTransform = void (*)(const float* m, std::size_t plane, const float* bias, int channels, bool leaky,
                                         bool add, float* const (&out)[kWinogradRows][kWinogradRows]);

struct WinogradTransforms {
    WinogradPatchTransform patch;
    WinogradOutputTransform output;
};
// The patch transform with V rounded to bfloat16 as it is stored (Precision::BFloat16).
using WinogradPatchTransformBf16 = void (*)(const float* const (&rows)[kWinogradPatch], std::size_t pixelStride,
                                            int channels, std::size_t plane, std::uint16_t* dst);

#if AFFINITY_HAVE_AVX512_KERNEL
// The 16-lane transforms (winograd_conv_avx512.cpp; call only where cpuHasAvx512()).
WinogradTransforms winogradTransformsAvx512();
// The 16-lane bfloat16 patch transform (bf16_gemm_avx512.cpp; call only where cpuHasAvx512Bf16()).
WinogradPatchTransformBf16 winogradPatchTransformBf16();
#endif

// Internal linkage: each instruction set's translation unit keeps its own copies.
namespace {
namespace winograd_lines {

template <class V>
V loadLanes(const float* p, int count) {
    return count == V::kLanes ? V::loadu(p) : V::loadPartial(p, count);
}
template <class V>
void storeLanes(V v, float* p, int count) {
    if (count == V::kLanes)
        v.storeu(p);
    else
        v.storePartial(p, count);
}
// Lanes [0, count) rounded to bfloat16: specialised for Float16 where AVX512-BF16 is compiled
// (bf16_gemm_avx512.cpp); no other translation unit stores bfloat16.
template <class V>
void storeLanes(V v, std::uint16_t* p, int count);

// t = B^T d for one line of six vectors (points 0, 1, -1, 2, -2, infinity; Lavin and Gray):
//   B^T = [4  0 -5  0 1 0;  0 -4 -4  1 1 0;  0 4 -4 -1 1 0;
//          0 -2 -1  2 1 0;  0  2 -1 -2 1 0;  0 4  0 -5 0 1]
template <class V>
inline void inputLine(const V (&d)[kWinogradPatch], V (&t)[kWinogradPatch]) {
    const V two = V::broadcast(2.0f), four = V::broadcast(4.0f), minusTwo = V::broadcast(-2.0f),
            minusFour = V::broadcast(-4.0f), minusFive = V::broadcast(-5.0f);
    const V d42 = d[4] - d[2], d31 = d[3] - d[1];
    t[0] = fma(four, d[0], fma(minusFive, d[2], d[4]));
    t[1] = fma(minusFour, d[1] + d[2], d[3] + d[4]);
    t[2] = fma(four, d[1] - d[2], d[4] - d[3]);
    t[3] = fma(two, d31, d42);
    t[4] = fma(minusTwo, d31, d42);
    t[5] = fma(four, d[1], fma(minusFive, d[3], d[5]));
}

// y = A^T m for one line of six vectors:
//   A^T = [1 1 1 1 1 0;  0 1 -1 2 -2 0;  0 1 1 4 4 0;  0 1 -1 8 -8 1]
template <class V>
inline void outputLine(const V (&m)[kWinogradPatch], V (&y)[kWinogradRows]) {
    const V two = V::broadcast(2.0f), four = V::broadcast(4.0f), eight = V::broadcast(8.0f);
    const V sum12 = m[1] + m[2], diff12 = m[1] - m[2], sum34 = m[3] + m[4], diff34 = m[3] - m[4];
    y[0] = (m[0] + sum12) + sum34;
    y[1] = fma(two, diff34, diff12);
    y[2] = fma(four, sum34, sum12);
    y[3] = fma(eight, diff34, diff12) + m[5];
}

// T: float, or std::uint16_t for V stored as bfloat16.
template <class V, class T = float>
void transformPatch(const float* const (&rows)[kWinogradPatch], std::size_t pixelStride, int channels,
                    std::size_t plane, T* dst) {
    constexpr int P = kWinogradPatch;
    for (int c = 0; c < channels; c += V::kLanes) {
        const int lanes = std::min(V::kLanes, channels - c);
        V across[P][P];  // [patch row][column of V]
        for (int i = 0; i < P; ++i) {
            V d[P];
            for (int j = 0; j < P; ++j) d[j] = loadLanes<V>(rows[i] + std::size_t(j) * pixelStride + c, lanes);
            inputLine(d, across[i]);
        }
        for (int j = 0; j < P; ++j) {
            V column[P], v[P];
            for (int i = 0; i < P; ++i) column[i] = across[i][j];
            inputLine(column, v);
            for (int i = 0; i < P; ++i) storeLanes(v[i], dst + std::size_t(i * P + j) * plane + c, lanes);
        }
    }
}

template <class V>
void transformOutput(const float* m, std::size_t plane, const float* bias, int channels, bool leaky, bool add,
                     float* const (&out)[kWinogradRows][kWinogradRows]) {
    constexpr int P = kWinogradPatch, R = kWinogradRows;
    const V slope = V::broadcast(0.01f);
    for (int o = 0; o < channels; o += V::kLanes) {
        const int lanes = std::min(V::kLanes, channels - o);
        V down[R][P];  // [output row][column of M]
        for (int j = 0; j < P; ++j) {
            V column[P], y[R];
            for (int i = 0; i < P; ++i) column[i] = loadLanes<V>(m + std::size_t(i * P + j) * plane + o, lanes);
            outputLine(column, y);
            for (int r = 0; r < R; ++r) down[r][j] = y[r];
        }
        const V b = loadLanes<V>(bias + o, lanes);
        for (int r = 0; r < R; ++r) {
            V y[R];
            outputLine(down[r], y);
            for (int q = 0; q < R; ++q) {
                V value = y[q] + b;
                if (add) value = loadLanes<V>(out[r][q] + o, lanes) + value;
                if (leaky) value = max(value, value * slope);
                storeLanes(value, out[r][q] + o, lanes);
            }
        }
    }
}

}  // namespace winograd_lines
}  // namespace
}  // namespace affinity
