// The convolution kernel's AVX-512 path: conv_blocks.h instantiated with 16-lane vectors.
// Built with -march=x86-64-v4 (core/CMakeLists.txt) and entered only after a run-time CPU
// check, so the library still runs on AVX2-only machines. Where the cores have full-width
// 512-bit FMA units (Zen 5), this doubles the convolutions' throughput over AVX2.
#include "kernels/conv_blocks.h"
#include "kernels/simd16.h"

namespace affinity {

void convolveRangeAvx512(const ConvBlockArgs& a, int vectors, int x0, int x1, float* outRow) {
    // A last vector with at most 8 lanes used runs at half width (conv_blocks.h, accumulate()).
    const bool halfTail = a.tailLanes <= 8;
    if (vectors == 2)
        halfTail ? convolveRange<Float16, 2, true>(a, x0, x1, outRow) : convolveRange<Float16, 2>(a, x0, x1, outRow);
    else
        halfTail ? convolveRange<Float16, 1, true>(a, x0, x1, outRow) : convolveRange<Float16, 1>(a, x0, x1, outRow);
}

}  // namespace affinity
