#pragma once
// The size of a denoising network (docs/MODEL.md): embedding widths, U-Net levels, and the
// affinity kernel settings. Plain C++ (no torch), so tools can describe models cheaply.
#include <cstdint>
#include <string>
#include <vector>

namespace affinity {
class Weights;
}

namespace affinity::train {

// A run of 3x3 convolutions (one U-Net level or the bottleneck): the output width of each.
struct ConvStackSpec {
    std::vector<int> widths;
    int outWidth() const { return widths.empty() ? 0 : widths.back(); }
};

// A model's sizes.
struct ModelConfig {
    std::vector<int> embedWidths;        // output width of each embedding layer; the last is E
    std::vector<ConvStackSpec> encoder;  // level 0 (full resolution) first
    ConvStackSpec bottleneck;
    std::vector<ConvStackSpec> decoder;  // decoder[l] runs at level l; as many as encoder levels
    int kernels = 3;                     // K: dilated affinity kernels, the last one also temporal
    int affinityFeatures = 8;            // F: affinity features per kernel
    int kernelSize = 5;                  // T: spatial taps per side (odd)
    // Not part of the network: whether the core restores light after the kernels (docs/MODEL.md
    // section 10). Kept from the weights a training starts from, written back on export.
    bool lightRestoration = false;
    // The temporal taps' weights times this / 100 (docs/MODEL.md section 7; config.temporal_gain_percent,
    // absent: 100). Part of the network: training applies it too, and keeps it on export.
    int temporalGainPercent = 100;

    int embeddingChannels() const { return embedWidths.empty() ? 0 : embedWidths.back(); }
    // Channels the moving average accumulates and the kernels filter: RGB radiance.
    static constexpr int kSignalChannels = 3;
    // Head channels per kernel: features, bandwidth, centre weight.
    int kernelChannels() const { return affinityFeatures + 2; }
    // P = K kernelChannels() + 2: the kernels' parameters; temporal bandwidth, lambda.
    int headChannels() const { return kernels * kernelChannels() + 2; }
};

// Throws affinity::Error naming the first inconsistency (sizes < 1, even T, level counts).
void validateConfig(const ModelConfig& config);

// Named sizes: "tiny", "small" and "medium" (the shipped models' sizes; tiny also for the tests'
// quick runs), "paper" (widths like the paper's third-party reimplementations: never trained,
// kept because scripts/bench_denoiser.sh times it as the ladder's paper-sized point).
std::vector<std::string> presetNames();
// Throws affinity::Error for unknown names.
ModelConfig presetConfig(const std::string& name);

// Reads the structure back from a weights file's tensors (docs/MODEL.md sections 4 and 8) and
// checks every shape against it; throws affinity::Error naming the source and the tensor, or the
// switch of a removed variant that the file turns on (config.source_weights,
// config.emission_lambda, config.albedo_demodulation, config.emission_bypass).
ModelConfig configFromWeights(const Weights& weights);

// The float tensors of a model as docs/MODEL.md names them, with their shapes, in the order
// the training code registers them.
struct TensorSpec {
    std::string name;
    std::vector<std::int64_t> shape;
};
std::vector<TensorSpec> parameterSpecs(const ModelConfig& config);
std::int64_t parameterCount(const ModelConfig& config);

// Approximate arithmetic per output pixel (a multiply-add counts 2, an exp 1), ignoring the
// rounding up of odd sizes at coarse levels.
struct FlopCount {
    double embeddingPerSample = 0;  // the MLP on one sample
    double unetPerPixel = 0;        // U-Net including the head, per full-resolution pixel
    double filterPerPixel = 0;      // warps, accumulation and every affinity kernel
    double perPixel(int spp) const { return embeddingPerSample * spp + unetPerPixel + filterPerPixel; }
};
FlopCount flopCount(const ModelConfig& config);

}  // namespace affinity::train
