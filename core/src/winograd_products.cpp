#include "winograd_products.h"

#include "aligned_allocator.h"

namespace affinity {

void winogradProducts(const PackedConv* fp32, const std::vector<PackedGemmBf16>& bf16, int positions,
                      const float* v, std::size_t inPlane, int tiles, float* m, std::size_t outPlane) {
    const int in = fp32[0].inChannels();
    if (bf16.empty()) {
        for (int p = 0; p < positions; ++p) {
            const ConvSource position{v + std::size_t(p) * inPlane, in};
            convolveRow(fp32[p], &position, 1, 1, tiles, 0, 0, tiles, Activation::None, m + std::size_t(p) * outPlane);
        }
        return;
    }
    thread_local AlignedVector<std::uint16_t> rounded;  // per thread, reused from call to call
    const std::size_t values = std::size_t(positions) * inPlane;
    if (rounded.size() < values) rounded.resize(values);
    convertToBf16(v, values, rounded.data());
    for (int p = 0; p < positions; ++p)
        gemmBf16(bf16[std::size_t(p)], rounded.data() + std::size_t(p) * inPlane, std::size_t(in), tiles,
                 m + std::size_t(p) * outPlane, std::size_t(bf16[std::size_t(p)].outChannels()));
}

std::vector<PackedGemmBf16> bf16Positions(const std::vector<std::vector<float>>& u, int outChannels,
                                          int inChannels, bool bfloat16) {
    std::vector<PackedGemmBf16> packed;
    if (!bfloat16 || inChannels % 2 != 0) return packed;
    for (const std::vector<float>& weights : u) packed.emplace_back(weights.data(), outChannels, inChannels);
    return packed;
}

}  // namespace affinity
