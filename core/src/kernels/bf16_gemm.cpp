#include "kernels/bf16_gemm.h"

#include <cstring>
#include <string>

#include "affinity/error.h"
#include "kernels/aligned_allocator.h"
#include "kernels/conv_kernel.h"

namespace affinity {

#if AFFINITY_HAVE_AVX512_KERNEL
void gemmBf16Avx512(const PackedGemmBf16& w, const std::uint16_t* x, std::size_t xStride, int rows, float* out,
                    std::size_t outStride, bool leaky);
void convertToBf16Avx512(const float* src, std::size_t count, std::uint16_t* dst);
#endif

bool cpuHasAvx512Bf16() {
    // The AVX-512 kernels' own check, plus the bfloat16 instructions.
    static const bool has = cpuHasAvx512() && __builtin_cpu_supports("avx512bf16");
    return has;
}

std::uint16_t toBFloat16(float x) {
    std::uint32_t bits;
    std::memcpy(&bits, &x, sizeof bits);
    bits += 0x7FFFu + ((bits >> 16) & 1u);  // round to nearest, ties to even
    return std::uint16_t(bits >> 16);
}

PackedGemmBf16::PackedGemmBf16(const float* torchWeights, int outChannels, int inChannels, const float* bias)
    : out_(outChannels), in_(inChannels) {
    if (outChannels <= 0 || inChannels <= 0 || inChannels % 2 != 0)
        throw Error("bfloat16 product: unsupported shape [" + std::to_string(outChannels) + ", " +
                    std::to_string(inChannels) + "] (input channels must be even)");
    if (!cpuHasAvx512Bf16()) throw Error("bfloat16 product: this CPU or build has no AVX512-BF16");
    constexpr int kLanes = 16;
    const int pairs = inChannels / 2;
    std::size_t total = 0;
    for (int first = 0; first < outChannels;) {
        const Block block{first, outChannels - first > kLanes ? 2 : 1, total};
        blocks_.push_back(block);
        total += std::size_t(pairs) * block.vectors * kLanes;
        first += block.vectors * kLanes;
    }
    words_.assign(total, 0u);
    bias_.assign(std::size_t(blocks_.back().firstChannel + blocks_.back().vectors * kLanes), 0.0f);
    if (bias)
        for (int o = 0; o < outChannels; ++o) bias_[std::size_t(o)] = bias[o];
    for (const Block& block : blocks_) {
        const int lanes = block.vectors * kLanes;
        for (int k = 0; k < pairs; ++k)
            for (int l = 0; l < lanes; ++l) {
                const int o = block.firstChannel + l;
                if (o >= outChannels) continue;
                const float* row = torchWeights + std::size_t(o) * inChannels + 2 * k;
                words_[block.offset + std::size_t(k) * lanes + l] =
                    std::uint32_t(toBFloat16(row[0])) | (std::uint32_t(toBFloat16(row[1])) << 16);
            }
    }
}

void gemmBf16(const PackedGemmBf16& w, const std::uint16_t* x, std::size_t xStride, int rows, float* out,
              std::size_t outStride, bool leaky) {
#if AFFINITY_HAVE_AVX512_KERNEL
    gemmBf16Avx512(w, x, xStride, rows, out, outStride, leaky);  // the constructor checked the CPU
#else
    (void)w, (void)x, (void)xStride, (void)rows, (void)out, (void)outStride, (void)leaky;
    throw Error("bfloat16 product: this build has no AVX-512 kernels");
#endif
}

void gemmBf16(const PackedGemmBf16& w, const float* x, int rows, float* out, std::size_t outStride, bool leaky) {
    thread_local AlignedVector<std::uint16_t> rounded;  // per thread, reused from call to call
    const std::size_t values = std::size_t(rows) * w.inChannels();
    if (rounded.size() < values) rounded.resize(values);
    convertToBf16(x, values, rounded.data());
    gemmBf16(w, rounded.data(), std::size_t(w.inChannels()), rows, out, outStride, leaky);
}

void convertToBf16(const float* src, std::size_t count, std::uint16_t* dst) {
#if AFFINITY_HAVE_AVX512_KERNEL
    if (cpuHasAvx512Bf16()) return convertToBf16Avx512(src, count, dst);
#endif
    for (std::size_t i = 0; i < count; ++i) dst[i] = toBFloat16(src[i]);
}

}  // namespace affinity
