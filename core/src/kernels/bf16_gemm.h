#pragma once
// Matrix products in bfloat16 with FP32 accumulation (AVX512-BF16: VDPBF16PS does two
// multiply-adds per 32-bit lane, twice the FP32 FMA's rate on the same units). Used, where the
// CPU has it and the model asks for it (Precision::BFloat16, affinity/precision.h), by the
// Winograd convolutions' per-position products, the 1x1 layers and the embedding: inputs and
// weights keep 8 significant bits (a relative rounding of at most 2^-8 each), products and sums
// stay FP32. Rows of the input are bfloat16 values in pairs of consecutive channels, so a
// channel count must be even.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "kernels/aligned_allocator.h"

namespace affinity {

// Whether this build has the bfloat16 kernel and this CPU can run it (AVX-512 and AVX512-BF16);
// the same as the public bfloat16Supported().
bool cpuHasAvx512Bf16();

// x rounded to the nearest bfloat16 (ties to even), as its 16 bits; x finite.
std::uint16_t toBFloat16(float x);

// A [outChannels][inChannels] weight matrix (torch's 1x1 layout) repacked for gemmBf16: blocks
// of up to 32 output channels, per block [input pair][lanes] 32-bit words, each two bfloat16
// weights of consecutive input channels (lower channel in the low half, as VDPBF16PS pairs them).
class PackedGemmBf16 {
public:
    PackedGemmBf16() = default;
    // bias: [outChannels] (kept in FP32) or null (zero). Throws affinity::Error for an odd
    // inChannels or where !cpuHasAvx512Bf16().
    PackedGemmBf16(const float* torchWeights, int outChannels, int inChannels, const float* bias = nullptr);

    int outChannels() const { return out_; }
    int inChannels() const { return in_; }
    struct Block {
        int firstChannel;
        int vectors;         // 16-lane vectors of output channels: 1 or 2
        std::size_t offset;  // into words()
    };
    const std::vector<Block>& blocks() const { return blocks_; }
    const std::uint32_t* words() const { return words_.data(); }
    const float* bias() const { return bias_.data(); }  // padded to the blocks' lanes

private:
    int out_ = 0, in_ = 0;
    std::vector<Block> blocks_;
    AlignedVector<std::uint32_t> words_;
    AlignedVector<float> bias_;
};

// out[r][o] = act(bias[o] + sum over c of x[r][c] w[o][c]) for rows r < rows, act the leaky
// ReLU of slope 0.01 where `leaky`, else none: x holds bfloat16 values, row r at x + r * xStride
// (in bfloat16 values, even), out row r at out + r * outStride (floats). Each output is
// accumulated over the input pairs in order, so the split into rows changes no value.
void gemmBf16(const PackedGemmBf16& w, const std::uint16_t* x, std::size_t xStride, int rows, float* out,
              std::size_t outStride, bool leaky = false);

// The same on FP32 rows (x: rows x inChannels floats, contiguous), rounded to bfloat16 first.
void gemmBf16(const PackedGemmBf16& w, const float* x, int rows, float* out, std::size_t outStride, bool leaky = false);

// dst[i] = toBFloat16(src[i]) for i < count (vectorised where cpuHasAvx512Bf16()).
void convertToBf16(const float* src, std::size_t count, std::uint16_t* dst);

}  // namespace affinity
