#pragma once
// The per-position products of a Winograd form (winograd_conv.h, coarse_winograd.h): for each
// position p of the transformed tiles, m[p] = v[p] x U[p], a 1x1 convolution of the tiles' V by
// the transformed weights, in FP32 (PackedConv) or, where the layer was built for
// Precision::BFloat16, in bfloat16 (bf16_gemm.h) on V that the patch transform stored rounded.
#include <cstddef>
#include <vector>

#include "kernels/bf16_gemm.h"
#include "kernels/conv_kernel.h"

namespace affinity {

// v: `positions` planes of `inPlane` values, tiles rows of inChannels each; m: planes of
// `outPlane` floats, tiles rows of outChannels.
void winogradProducts(const PackedConv* u, int positions, const float* v, std::size_t inPlane, int tiles, float* m,
                      std::size_t outPlane);
void winogradProducts(const std::vector<PackedGemmBf16>& u, const std::uint16_t* v, std::size_t inPlane, int tiles,
                      float* m, std::size_t outPlane);

// The bfloat16 forms of a layer's per-position weights u[p] ([out][in] each), or none: for
// Precision::Float32, and for an odd input channel count (bfloat16 pairs channels; such a layer
// stays FP32). Throws affinity::Error where bfloat16 is asked for but the CPU lacks it.
std::vector<PackedGemmBf16> bf16Positions(const std::vector<std::vector<float>>& u, int outChannels, int inChannels,
                                          bool bfloat16);

}  // namespace affinity
