#include "affinity_model.h"

#include <torch/nn/functional/conv.h>
#include <torch/nn/modules/linear.h>
#include <torch/utils.h>

#include <string>

#include "affinity/error.h"
#include "affinity/features.h"

namespace affinity::train {
namespace {

constexpr double kLeakySlope = 0.01;

torch::nn::Conv2d conv(int in, int out, int size) {
    return torch::nn::Conv2d(torch::nn::Conv2dOptions(in, out, size).padding(size / 2).bias(true));
}

std::string shapeText(const torch::Tensor& tensor) {
    std::string text = "[";
    for (std::int64_t i = 0; i < tensor.dim(); ++i) text += (i ? ", " : "") + std::to_string(tensor.size(i));
    return text + "]";
}

}  // namespace

RecurrentState RecurrentState::detached() const {
    if (empty()) return {};
    return {embedding.detach(), radiance.detach(), output.detach(), features.detach(), exposure};
}

ConvStackImpl::ConvStackImpl(int inChannels, const ConvStackSpec& spec) {
    for (std::size_t j = 0; j < spec.widths.size(); ++j) {
        convs_.push_back(register_module("conv" + std::to_string(j), conv(inChannels, spec.widths[j], 3)));
        inChannels = spec.widths[j];
    }
}

torch::Tensor ConvStackImpl::forward(torch::Tensor x) {
    for (torch::nn::Conv2d& layer : convs_) x = torch::leaky_relu(layer(x), kLeakySlope);
    return x;
}

UNetImpl::UNetImpl(int inChannels, const ModelConfig& config) {
    // Registration order = parameterSpecs() order = the order initialisation draws numbers in.
    const int levels = int(config.encoder.size());
    std::vector<int> skipWidths;
    for (int l = 0; l < levels; ++l) {
        const ConvStackSpec& spec = config.encoder[std::size_t(l)];
        encoder_.push_back(register_module("enc" + std::to_string(l), ConvStack(inChannels, spec)));
        inChannels = spec.outWidth();
        skipWidths.push_back(inChannels);
    }
    bottleneck_ = register_module("bottleneck", ConvStack(inChannels, config.bottleneck));
    inChannels = config.bottleneck.outWidth();
    decoder_.resize(std::size_t(levels), nullptr);
    for (int l = levels - 1; l >= 0; --l) {
        const ConvStackSpec& spec = config.decoder[std::size_t(l)];
        decoder_[std::size_t(l)] =
            register_module("dec" + std::to_string(l), ConvStack(inChannels + skipWidths[std::size_t(l)], spec));
        inChannels = spec.outWidth();
    }
    head_ = register_module("head", conv(inChannels, config.headChannels(), 1));
}

torch::Tensor UNetImpl::forward(const torch::Tensor& input) {
    std::vector<torch::Tensor> skips;
    torch::Tensor x = input;
    for (std::size_t l = 0; l < encoder_.size(); ++l) {
        x = encoder_[l](l == 0 ? x : maxPool2x2(x));
        skips.push_back(x);
    }
    x = bottleneck_(maxPool2x2(x));
    for (std::size_t l = decoder_.size(); l-- > 0;) {
        const torch::Tensor& skip = skips[l];
        x = upsampleNearest(x, skip.size(2), skip.size(3));
        x = decoder_[l](torch::cat({x, skip}, 1));  // upsampled channels first
    }
    return head_(x);
}

AffinityModelImpl::AffinityModelImpl(const ModelConfig& config) : config_(config) {
    validateConfig(config_);
    embed_ = register_module("embed", torch::nn::ModuleList());
    int in = kFeatureCount;
    for (int width : config_.embedWidths) {
        embed_->push_back(torch::nn::Linear(torch::nn::LinearOptions(in, width).bias(true)));
        in = width;
    }
    unet_ = register_module("unet", UNet(2 * config_.embeddingChannels(), config_));
}

torch::Tensor AffinityModelImpl::embed(const torch::Tensor& networkInput) {
    const std::int64_t batch = networkInput.size(0), spp = networkInput.size(1);
    const std::int64_t height = networkInput.size(3), width = networkInput.size(4);
    // Per-sample dense layers as 1x1 convolutions: oneDNN runs them fast, reference BLAS does not.
    torch::Tensor x = networkInput.reshape({batch * spp, kFeatureCount, height, width});
    const std::size_t layers = embed_->size();
    for (std::size_t i = 0; i < layers; ++i) {
        const auto& linear = embed_[i]->as<torch::nn::Linear>();
        const torch::Tensor weight = linear->weight.view({linear->weight.size(0), linear->weight.size(1), 1, 1});
        x = torch::nn::functional::conv2d(x, weight, torch::nn::functional::Conv2dFuncOptions().bias(linear->bias));
        if (i + 1 < layers) x = torch::leaky_relu(x, kLeakySlope);
    }
    return x.view({batch, spp, x.size(1), height, width}).mean(1);
}

FrameResult AffinityModelImpl::forwardFrame(const FrameInput& frame, RecurrentState& state) {
    const torch::Tensor reference = embed_[0]->as<torch::nn::Linear>()->weight;
    const torch::TensorOptions options = reference.options();
    if (!frame.samples.defined() || frame.samples.dim() != 5 || frame.samples.size(2) != kFeatureCount) {
        throw Error("forwardFrame: samples must be [B, S, 18, H, W]");
    }
    const torch::Tensor samples = frame.samples.to(options);
    const std::int64_t batch = samples.size(0), height = samples.size(3), width = samples.size(4);
    if (batch < 1 || samples.size(1) < 1 || height < 1 || width < 1) throw Error("forwardFrame: the frame is empty");
    const std::vector<std::int64_t> motionShape{batch, 2, height, width}, validShape{batch, 1, height, width};
    if (!frame.motion.defined() || frame.motion.sizes() != motionShape) {
        throw Error("forwardFrame: motion must be [B, 2, H, W], got " +
                    (frame.motion.defined() ? shapeText(frame.motion) : std::string("nothing")));
    }
    if (!frame.valid.defined() || frame.valid.sizes() != validShape) {
        throw Error("forwardFrame: valid must be [B, 1, H, W], got " +
                    (frame.valid.defined() ? shapeText(frame.valid) : std::string("nothing")));
    }
    const torch::Tensor motion = frame.motion.to(options);
    const std::vector<std::int64_t> signalShape{batch, ModelConfig::kSignalChannels, height, width};
    const bool history = !state.empty() && state.output.sizes() == signalShape;

    FrameResult result;
    // Sections 1-2: sanitised inputs, per-sample embedding averaged per pixel.
    // A sequence keeps the exposure of its first frame (the core does the same).
    PreparedInputs prepared = prepareInputs(samples, history ? state.exposure : torch::Tensor());
    result.noisy = prepared.radiance;
    result.invalidCount = prepared.invalidCount;
    result.embedding = embed(prepared.networkInput);
    // What the moving average accumulates and the kernels filter: the noisy radiance.
    const torch::Tensor& current = prepared.radiance;

    // Section 3: histories (warped state where valid, the current frame elsewhere).
    torch::Tensor validMask = torch::zeros(validShape, options);
    torch::Tensor historyEmbedding = result.embedding, historySignal = current;
    if (history) {
        validMask = (frame.valid.to(options) > 0.5).to(options);
        const torch::Tensor use = validMask > 0.5;
        historyEmbedding = torch::where(use, warpBilinear(state.embedding, motion), result.embedding);
        historySignal = torch::where(use, warpCatmullRom(state.radiance, motion), current);
    }

    // Sections 4-5: U-Net and per-pixel parameters.
    result.head = unet_(torch::cat({result.embedding, historyEmbedding}, 1));
    const int K = config_.kernels, F = config_.affinityFeatures;
    for (int k = 0; k < K; ++k) {
        const std::int64_t base = std::int64_t(k) * config_.kernelChannels();
        result.kernels.push_back({result.head.narrow(1, base, F), result.head.narrow(1, base + F, 1),
                                  torch::sigmoid(result.head.narrow(1, base + F + 1, 1))});
    }
    const std::int64_t tail = std::int64_t(K) * config_.kernelChannels();
    result.temporalBandwidth = result.head.narrow(1, tail, 1);
    result.lambda = torch::sigmoid(result.head.narrow(1, tail + 1, 1));

    // Section 3 (continued): the learned moving averages.
    const torch::Tensor& lambda = result.lambda;
    const torch::Tensor accumulatedEmbedding = (1 - lambda) * result.embedding + lambda * historyEmbedding;
    result.accumulated = (1 - lambda) * current + lambda * historySignal;

    // Section 6: dilated kernels 0..K-2; section 7: the last one, with temporal taps.
    torch::Tensor filtered = result.accumulated;
    for (int k = 0; k + 1 < K; ++k) {
        filtered = affinityFilter(filtered, result.kernels[std::size_t(k)], config_.kernelSize, 1 << k);
    }
    const KernelParams& last = result.kernels.back();
    if (history) {
        // The model's temporal gain scales what every valid tap gives (docs/MODEL.md section 7).
        const torch::Tensor tapScale =
            config_.temporalGainPercent == 100 ? validMask : validMask * (config_.temporalGainPercent / 100.0);
        const TemporalTaps temporal{result.temporalBandwidth, warpCatmullRom(state.output, motion),
                                    warpBilinear(state.features, motion), tapScale};
        filtered = affinityFilterTemporal(filtered, last, config_.kernelSize, 1 << (K - 1), temporal);
    } else {
        filtered = affinityFilter(filtered, last, config_.kernelSize, 1 << (K - 1));
    }
    result.output = filtered;

    state = {accumulatedEmbedding, result.accumulated, filtered, last.features, prepared.exposure};
    return result;
}

std::vector<torch::Tensor> AffinityModelImpl::forwardSequence(const std::vector<FrameInput>& frames) {
    RecurrentState state;
    std::vector<torch::Tensor> outputs;
    outputs.reserve(frames.size());
    for (const FrameInput& frame : frames) outputs.push_back(forwardFrame(frame, state).output);
    return outputs;
}

AffinityModel makeModel(const ModelConfig& config, std::uint64_t seed) {
    torch::manual_seed(seed);
    return AffinityModel(config);
}

}  // namespace affinity::train
