#include "kernels/conv_kernel.h"

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <string>

#include "affinity/error.h"
#include "kernels/conv_blocks.h"
#include "kernels/simd8.h"

namespace affinity {

bool cpuHasAvx512() {
#if AFFINITY_HAVE_AVX512_KERNEL
    // What x86-64-v4 adds to v3 that the kernel's translation unit may use; libgcc's check also
    // asks the OS whether it saves the 512-bit registers.
    static const bool has = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
                            __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq") &&
                            __builtin_cpu_supports("avx512cd");
    return has;
#else
    return false;
#endif
}

ConvIsa defaultConvIsa() {
    static const ConvIsa isa = [] {
        const char* forced = std::getenv("AFFINITY_CONV_ISA");
        const bool avx2Asked = forced && std::strcmp(forced, "avx2") == 0;
        return cpuHasAvx512() && !avx2Asked ? ConvIsa::Avx512 : ConvIsa::Avx2;
    }();
    return isa;
}

PackedConv::PackedConv(const float* torchWeights, const float* bias, int outChannels, int inChannels, int size,
                       ConvIsa isa)
    : out_(outChannels), in_(inChannels), size_(size), isa_(isa) {
    if (outChannels <= 0 || inChannels <= 0 || size < 1 || size > 3)
        throw Error("convolution: unsupported shape [" + std::to_string(outChannels) + ", " +
                    std::to_string(inChannels) + ", " + std::to_string(size) + ", " + std::to_string(size) + "]");
    if (isa == ConvIsa::Avx512 && !cpuHasAvx512())
        throw Error("convolution: the AVX-512 kernel was asked for, but this CPU or build has no AVX-512");
    // Blocks of two vectors while more than one vector's worth of channels remains, then one.
    // With AVX-512, 24 channels run as one block of 16 + 8 lanes in one pass over the input, the
    // 8 at half width (conv_blocks.h): a separate AVX2 block of 8 made the whole frame slower
    // for its extra pass over the input.
    const int lanes = vectorLanes();
    for (int first = 0; first < outChannels;) {
        const Block block{first, outChannels - first > lanes ? 2 : 1, 0};
        blocks_.push_back(block);
        first += block.vectors * lanes;
    }
    const int taps = size * size;
    std::size_t total = 0;
    for (Block& block : blocks_) {
        block.offset = total;
        total += std::size_t(taps) * inChannels * block.vectors * lanes;
    }
    weights_.assign(total, 0.0f);
    bias_.assign(std::size_t(blocks_.back().firstChannel + blocks_.back().vectors * lanes), 0.0f);
    if (bias)
        for (int o = 0; o < outChannels; ++o) bias_[o] = bias[o];
    for (const Block& block : blocks_) {
        const int blockLanes = block.vectors * lanes;
        for (int tap = 0; tap < taps; ++tap) {
            for (int c = 0; c < inChannels; ++c) {
                float* dst = weights_.data() + block.offset + (std::size_t(tap) * inChannels + c) * blockLanes;
                for (int l = 0; l < blockLanes; ++l) {
                    const int o = block.firstChannel + l;
                    if (o < outChannels) dst[l] = torchWeights[(std::size_t(o) * inChannels + c) * taps + tap];
                }
            }
        }
    }
}

void convolveRow(const PackedConv& conv, const ConvSource* sources, int sourceCount, int height, int width, int y,
                 int x0, int x1, Activation activation, float* outputRow) {
    ConvPlacement centred;
    centred.originY = centred.originX = -(conv.size() / 2);
    centred.outPixelStride = conv.outChannels();
    convolveRowPlaced(conv, sources, sourceCount, height, width, y, x0, x1, activation, centred, outputRow);
}

void convolveRowPlaced(const PackedConv& conv, const ConvSource* sources, int sourceCount, int height, int width, int y,
                       int x0, int x1, Activation activation, const ConvPlacement& placement, float* outputRow) {
    ConvBlockArgs a{};
    a.sources = sources;
    a.sourceCount = sourceCount;
    a.width = width;
    a.y = y;
    a.size = conv.size();
    a.originY = placement.originY;
    a.originX = placement.originX;
    a.kyBegin = std::max(placement.originY, -y);
    a.kyEnd = std::min(placement.originY + conv.size() - 1, height - 1 - y);
    a.outStride = placement.outPixelStride;
    a.leaky = activation == Activation::LeakyRelu;
    a.addToOutput = placement.addToOutput;
    const int lanes = conv.vectorLanes();
    for (const PackedConv::Block& block : conv.blocks()) {
        a.weights = conv.weights() + block.offset;
        a.bias = conv.bias() + block.firstChannel;
        a.tapStride = std::size_t(conv.inChannels()) * block.vectors * lanes;
        a.tailLanes = std::min(lanes, conv.outChannels() - block.firstChannel - (block.vectors - 1) * lanes);
        float* out = outputRow + block.firstChannel;
#if AFFINITY_HAVE_AVX512_KERNEL
        if (lanes == 16) {
            convolveRangeAvx512(a, block.vectors, x0, x1, out);
            continue;
        }
#endif
        if (block.vectors == 2)
            convolveRange<Float8, 2>(a, x0, x1, out);
        else
            convolveRange<Float8, 1>(a, x0, x1, out);
    }
}

}  // namespace affinity
