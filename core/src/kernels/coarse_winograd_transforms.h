#pragma once
// The transforms of the coarse Winograd form F(2x2, 2x2) (coarse_winograd.h) written once over
// the vector type: Float8 (coarse_winograd.cpp) and Float16 (winograd_conv_avx512.cpp)
// instantiate them. Every coefficient is 0 or +-1, so the transforms are adds and subtracts in a
// fixed order and the two widths give the same bits.
#include <algorithm>
#include <cstddef>

#include "kernels/winograd_transforms.h"  // loadLanes, storeLanes

namespace affinity {

// V = B^T d B, B^T = [1 -1 0; 0 1 0; 0 -1 1], for the `channels` channels of a 3x3 patch (pixel
// (i, j) at rows[i] + j * pixelStride); position i * 3 + j goes to dst + (i * 3 + j) * plane.
using CoarsePatchTransform = void (*)(const float* const (&rows)[3], std::size_t pixelStride, int channels,
                                      std::size_t plane, float* dst);
// Y = A^T M A + bias, A^T = [1 1 0; 0 1 1], for `channels` output channels of one tile; position
// (i, j) of M at m + (i * 3 + j) * plane; output (r, q) to out[r][q].
using CoarseOutputTransform = void (*)(const float* m, std::size_t plane, const float* bias, int channels,
                                       float* const (&out)[2][2]);

struct CoarseWinogradTransforms {
    CoarsePatchTransform patch;
    CoarseOutputTransform output;
};
// The patch transform with V rounded to bfloat16 as it is stored (Precision::BFloat16).
using CoarsePatchTransformBf16 = void (*)(const float* const (&rows)[3], std::size_t pixelStride, int channels,
                                          std::size_t plane, std::uint16_t* dst);

#if AFFINITY_HAVE_AVX512_KERNEL
// The 16-lane transforms (winograd_conv_avx512.cpp; call only where cpuHasAvx512()).
CoarseWinogradTransforms coarseWinogradTransformsAvx512();
// The 16-lane bfloat16 patch transform (bf16_gemm_avx512.cpp; call only where cpuHasAvx512Bf16()).
CoarsePatchTransformBf16 coarsePatchTransformBf16();
#endif

// Internal linkage: each instruction set's translation unit keeps its own copies.
namespace {
namespace coarse_lines {

// T: float, or std::uint16_t for V stored as bfloat16.
template <class V, class T = float>
void transformPatch(const float* const (&rows)[3], std::size_t pixelStride, int channels, std::size_t plane, T* dst) {
    using winograd_lines::loadLanes, winograd_lines::storeLanes;
    for (int c = 0; c < channels; c += V::kLanes) {
        const int lanes = std::min(V::kLanes, channels - c);
        V across[3][3];
        for (int i = 0; i < 3; ++i) {
            const V d0 = loadLanes<V>(rows[i] + c, lanes), d1 = loadLanes<V>(rows[i] + pixelStride + c, lanes);
            const V d2 = loadLanes<V>(rows[i] + 2 * pixelStride + c, lanes);
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

template <class V>
void transformOutput(const float* m, std::size_t plane, const float* bias, int channels, float* const (&out)[2][2]) {
    using winograd_lines::loadLanes, winograd_lines::storeLanes;
    for (int o = 0; o < channels; o += V::kLanes) {
        const int lanes = std::min(V::kLanes, channels - o);
        V down[2][3];
        for (int j = 0; j < 3; ++j) {
            const V m0 = loadLanes<V>(m + std::size_t(j) * plane + o, lanes);
            const V m1 = loadLanes<V>(m + std::size_t(3 + j) * plane + o, lanes);
            const V m2 = loadLanes<V>(m + std::size_t(6 + j) * plane + o, lanes);
            down[0][j] = m0 + m1;
            down[1][j] = m1 + m2;
        }
        const V b = loadLanes<V>(bias + o, lanes);
        for (int r = 0; r < 2; ++r) {
            storeLanes(down[r][0] + down[r][1] + b, out[r][0] + o, lanes);
            storeLanes(down[r][1] + down[r][2] + b, out[r][1] + o, lanes);
        }
    }
}

}  // namespace coarse_lines
}  // namespace
}  // namespace affinity
