#include "kernels/winograd_products.h"

namespace affinity {

void winogradProducts(const PackedConv* u, int positions, const float* v, std::size_t inPlane, int tiles, float* m,
                      std::size_t outPlane) {
    for (int p = 0; p < positions; ++p) {
        const ConvSource position{v + std::size_t(p) * inPlane, u[p].inChannels()};
        convolveRow(u[p], &position, 1, 1, tiles, 0, 0, tiles, Activation::None, m + std::size_t(p) * outPlane);
    }
}

void winogradProducts(const std::vector<PackedGemmBf16>& u, const std::uint16_t* v, std::size_t inPlane, int tiles,
                      float* m, std::size_t outPlane) {
    for (std::size_t p = 0; p < u.size(); ++p)
        gemmBf16(u[p], v + p * inPlane, std::size_t(u[p].inChannels()), tiles, m + p * outPlane,
                 std::size_t(u[p].outChannels()));
}

std::vector<PackedGemmBf16> bf16Positions(const std::vector<std::vector<float>>& u, int outChannels, int inChannels,
                                          bool bfloat16) {
    std::vector<PackedGemmBf16> packed;
    if (!bfloat16 || inChannels % 2 != 0) return packed;
    for (const std::vector<float>& weights : u) packed.emplace_back(weights.data(), outChannels, inChannels);
    return packed;
}

}  // namespace affinity
