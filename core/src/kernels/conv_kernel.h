#pragma once
// The register-blocked convolution kernel behind Conv2d (3x3 and 1x1) and the embedding's
// dense layers (a dense layer is a 1x1 convolution over a row of samples). NHWC in and out,
// vectorised over output channels with AVX2 or, where the CPU has it, AVX-512; no threading:
// callers split the output into rows and column ranges. Every output value is accumulated in
// the same fixed order (bias, then taps row-major, then input channels in concatenation order)
// whatever the split and the vector width, so results depend neither on how work is divided
// among threads nor on the instruction set.
#include <cstddef>
#include <vector>

#include "kernels/aligned_allocator.h"

namespace affinity {

enum class Activation { None, LeakyRelu };  // leaky ReLU slope 0.01

// The kernel's vector width: 8 lanes (AVX2 + FMA, the build's baseline) or 16 (AVX-512).
enum class ConvIsa { Avx2, Avx512 };
// Whether this build has the AVX-512 path and this CPU (and OS) can run it.
bool cpuHasAvx512();
// Avx512 where cpuHasAvx512(), unless the environment variable AFFINITY_CONV_ISA=avx2 asks
// for the AVX2 path (benchmarks compare the two); read once.
ConvIsa defaultConvIsa();

// One input of a convolution: an NHWC image of the output's height and width, or, when
// `upsampled`, of half of it (rounded up) read as its nearest-neighbour 2x upsampling: output
// pixel (y, x) sees source pixel (y / 2, x / 2). The decoder reads its coarser level that way
// instead of materialising the upsampled map.
struct ConvSource {
    const float* data;
    int channels;
    bool upsampled = false;
};

// Weights and bias of a size x size convolution (size 1, 2 or 3), repacked for the kernel.
class PackedConv {
public:
    PackedConv() = default;
    // torchWeights: [outChannels][inChannels][size][size]; bias: [outChannels] or null (zero).
    // Throws affinity::Error for Avx512 where !cpuHasAvx512().
    PackedConv(const float* torchWeights, const float* bias, int outChannels, int inChannels, int size,
               ConvIsa isa = defaultConvIsa());

    int outChannels() const { return out_; }
    int inChannels() const { return in_; }
    int size() const { return size_; }

    // Lanes per vector: 8 (AVX2) or 16 (AVX-512).
    int vectorLanes() const { return isa_ == ConvIsa::Avx512 ? 16 : 8; }
    // Output channels are split into blocks of one or two vectors; block b holds weights
    // [tap][inChannel][vectors * vectorLanes()] (zero past outChannels).
    struct Block {
        int firstChannel;
        int vectors;
        std::size_t offset;  // into weights(), in floats
    };
    const std::vector<Block>& blocks() const { return blocks_; }
    const float* weights() const { return weights_.data(); }
    const float* bias() const { return bias_.data(); }  // padded to the block lanes

private:
    int out_ = 0, in_ = 0, size_ = 0;
    ConvIsa isa_ = ConvIsa::Avx2;
    std::vector<Block> blocks_;
    AlignedVector<float> weights_;
    AlignedVector<float> bias_;
};

// Computes output row y, columns [x0, x1), all output channels, of
// act(conv(concat(sources)) + bias) with zero padding, for images of height x width.
// outputRow points at column 0 of row y of an NHWC output with conv.outChannels() channels.
// The sources' channel counts must add up to conv.inChannels(); the output must not alias them.
// An upsampled source is (height + 1) / 2 x (width + 1) / 2.
void convolveRow(const PackedConv& conv, const ConvSource* sources, int sourceCount, int height, int width, int y,
                 int x0, int x1, Activation activation, float* outputRow);

// Where a convolution's window sits and where its output goes, for convolveRowPlaced: output
// pixel (y, x) reads the size x size taps (y + originY + i, x + originX + j) and is written
// outPixelStride floats after pixel x - 1; with addToOutput it starts from the value already
// there instead of the bias. convolveRow is origin -size / 2, stride outChannels, no adding.
struct ConvPlacement {
    int originY = 0, originX = 0;
    int outPixelStride = 0;
    bool addToOutput = false;
};
void convolveRowPlaced(const PackedConv& conv, const ConvSource* sources, int sourceCount, int height, int width, int y,
                       int x0, int x1, Activation activation, const ConvPlacement& placement, float* outputRow);

}  // namespace affinity
