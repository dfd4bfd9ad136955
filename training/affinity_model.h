#pragma once
// The denoising network of docs/MODEL.md as libtorch modules. Parameter names
// (named_parameters()) are exactly the weights file's tensor names: embed.{i}.weight,
// unet.enc{l}.conv{j}.weight, unet.bottleneck.conv{j}.bias, unet.dec{l}.conv{j}.weight,
// unet.head.weight, ...
//
// Tensor layout (batch-friendly; B frames of B independent sequences advance together):
//   samples [B, S, 18, H, W] raw features (features.h order), motion [B, 2, H, W] (dx, dy)
//   in pixels, valid [B, 1, H, W] (history valid where > 0.5); outputs [B, 3, H, W] linear RGB.
// Computation follows the parameters' dtype (float32 by default; double for gradient checks).
#include <cstdint>
#include <vector>

#include <torch/nn/module.h>
#include <torch/nn/modules/container/modulelist.h>
#include <torch/nn/modules/conv.h>
#include <torch/nn/pimpl.h>

#include "affinity_ops.h"
#include "model_config.h"

namespace affinity::train {

// 3x3 convolutions with zero padding 1, each followed by leaky ReLU (0.01): conv0, conv1, ...
class ConvStackImpl : public torch::nn::Module {
public:
    ConvStackImpl(int inChannels, const ConvStackSpec& spec);
    torch::Tensor forward(torch::Tensor x);

private:
    std::vector<torch::nn::Conv2d> convs_;
};
TORCH_MODULE(ConvStack);

// Section 4: enc{l}, bottleneck, dec{l}, head.
class UNetImpl : public torch::nn::Module {
public:
    UNetImpl(int inChannels, const ModelConfig& config);
    torch::Tensor forward(const torch::Tensor& x);  // [B, 2E, H, W] -> [B, P, H, W]

private:
    std::vector<ConvStack> encoder_, decoder_;
    ConvStack bottleneck_{nullptr};
    torch::nn::Conv2d head_{nullptr};
};
TORCH_MODULE(UNet);

struct FrameInput {
    torch::Tensor samples;  // [B, S, 18, H, W]
    torch::Tensor motion;   // [B, 2, H, W]
    torch::Tensor valid;    // [B, 1, H, W]
};

// What a frame leaves for the next one (sections 3 and 7); undefined tensors = no history.
struct RecurrentState {
    torch::Tensor embedding;  // ē_t [B, E, H, W]
    torch::Tensor radiance;   // L̄_t [B, 3, H, W]
    torch::Tensor output;     // the last kernel's output O_t [B, 3, H, W]
    torch::Tensor features;   // f^{K-1}_t [B, F, H, W]
    torch::Tensor exposure;   // [B]: the sequence's exposure normalisation (prepareInputs), 0 while black
    bool empty() const { return !output.defined(); }
    // The same values cut from the autograd graph: truncated back-propagation through time.
    RecurrentState detached() const;
};

// One frame's result, with intermediates for debugging and for loss terms.
struct FrameResult {
    torch::Tensor output;               // O_t [B, 3, H, W]
    torch::Tensor noisy;                // L_t [B, 3, H, W]
    torch::Tensor embedding;            // e_t [B, E, H, W]
    torch::Tensor accumulated;          // L̄_t [B, 3, H, W]
    torch::Tensor head;                 // U-Net output [B, P, H, W]
    torch::Tensor lambda;               // [B, 1, H, W]
    torch::Tensor temporalBandwidth;    // b [B, 1, H, W]
    std::vector<KernelParams> kernels;  // K entries
    torch::Tensor invalidCount;         // [B] int64: sanitised radiance values
};

class AffinityModelImpl : public torch::nn::Module {
public:
    explicit AffinityModelImpl(const ModelConfig& config);

    const ModelConfig& config() const { return config_; }

    // Section 2 on the prepared network input [B, S, 18, H, W] -> e_t [B, E, H, W].
    torch::Tensor embed(const torch::Tensor& networkInput);
    // Sections 1-7 for one frame; reads and replaces `state`. An empty state, or a state of
    // another size, means no history (every pixel invalid).
    FrameResult forwardFrame(const FrameInput& frame, RecurrentState& state);
    // A whole sequence from an empty state: every frame's O_t.
    std::vector<torch::Tensor> forwardSequence(const std::vector<FrameInput>& frames);

private:
    ModelConfig config_;
    torch::nn::ModuleList embed_{nullptr};
    UNet unet_{nullptr};
};
TORCH_MODULE(AffinityModel);

// A model with freshly initialised parameters: the same (config, seed) always gives the
// same weights. Seeds torch's global generator (torch::manual_seed).
AffinityModel makeModel(const ModelConfig& config, std::uint64_t seed);

}  // namespace affinity::train
