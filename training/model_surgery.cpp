#include "model_surgery.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <string>

#include "affinity/error.h"
#include "model_config.h"
#include "network/network.h"

namespace affinity::train {

namespace {

NamedTensor copyOf(const TensorView& view) {
    NamedTensor tensor{view.name, view.dtype, view.shape, {}, {}};
    if (view.dtype == DType::Int32) {
        const auto* values = static_cast<const std::int32_t*>(view.data);
        tensor.ints.assign(values, values + view.count);
    } else {
        const auto* values = static_cast<const float*>(view.data);
        tensor.floats.assign(values, values + view.count);
    }
    return tensor;
}

// Every tensor of `weights`, copied.
std::vector<NamedTensor> copiesOf(const Weights& weights) {
    std::vector<NamedTensor> tensors;
    for (const std::string& name : weights.names()) tensors.push_back(copyOf(weights.tensor(name)));
    return tensors;
}

// The tensor called `name` in `tensors`; throws affinity::Error naming `what` (command and source).
NamedTensor& tensorNamed(std::vector<NamedTensor>& tensors, const std::string& name, const std::string& what) {
    for (NamedTensor& tensor : tensors)
        if (tensor.name == name) return tensor;
    throw Error(what + " has no tensor " + name);
}

// Where a run of a trained layer's input channels sits in the wider layer's input.
struct InputRun {
    int from = 0, count = 0, to = 0;
};

// One convolution of the U-Net (or the head): its tensor names and where its trained inputs go.
struct WidenedConv {
    std::string prefix;
    std::vector<InputRun> inputs;
};

// Every U-Net convolution in the order of parameterSpecs, with its trained input channels'
// places in the wider model: the decoder's input is the upsampled coarser level, then the skip.
std::vector<WidenedConv> widenedConvs(const ModelConfig& trained, const ModelConfig& wide) {
    std::vector<WidenedConv> convs;
    // A stack's first convolution reads `inputs`; each later one the trained channels before it.
    auto stack = [&](const std::string& prefix, const ConvStackSpec& trainedStack, std::vector<InputRun> inputs) {
        for (std::size_t j = 0; j < trainedStack.widths.size(); ++j) {
            convs.push_back({prefix + ".conv" + std::to_string(j), inputs});
            inputs = {{0, trainedStack.widths[j], 0}};
        }
        return inputs;
    };
    const int levels = int(trained.encoder.size());
    std::vector<InputRun> in = {{0, 2 * trained.embeddingChannels(), 0}};
    std::vector<int> skipBefore;
    for (int l = 0; l < levels; ++l) {
        const auto level = std::size_t(l);
        in = stack("unet.enc" + std::to_string(l), trained.encoder[level], in);
        skipBefore.push_back(trained.encoder[level].outWidth());
    }
    stack("unet.bottleneck", trained.bottleneck, in);
    int lowBefore = trained.bottleneck.outWidth(), lowAfter = wide.bottleneck.outWidth();
    for (int l = levels - 1; l >= 0; --l) {
        const auto level = std::size_t(l);
        stack("unet.dec" + std::to_string(l), trained.decoder[level],
              {{0, lowBefore, 0}, {lowBefore, skipBefore[level], lowAfter}});
        lowBefore = trained.decoder[level].outWidth();
        lowAfter = wide.decoder[level].outWidth();
    }
    convs.push_back({"unet.head", {{0, lowBefore, 0}}});
    return convs;
}

// Both models' structures agree except for wider (or equal) U-Net layers.
void checkWidenable(const ModelConfig& trained, const ModelConfig& wide, const std::string& source) {
    auto fail = [&](const std::string& what) {
        throw Error("widen: " + source + " does not fit the wider model: " + what);
    };
    if (trained.embedWidths != wide.embedWidths) fail("the embedding widths differ");
    if (trained.kernels != wide.kernels || trained.affinityFeatures != wide.affinityFeatures ||
        trained.kernelSize != wide.kernelSize)
        fail("the kernel settings (K, F, T) differ");
    if (trained.encoder.size() != wide.encoder.size()) fail("the U-Net level counts differ");
    auto sameDepth = [&](const ConvStackSpec& a, const ConvStackSpec& b, const std::string& name) {
        if (a.widths.size() != b.widths.size()) fail(name + " has a different number of convolutions");
        for (std::size_t j = 0; j < a.widths.size(); ++j)
            if (b.widths[j] < a.widths[j]) fail(name + " is narrower in the wider model");
    };
    for (std::size_t l = 0; l < trained.encoder.size(); ++l) {
        sameDepth(trained.encoder[l], wide.encoder[l], "encoder level " + std::to_string(l));
        sameDepth(trained.decoder[l], wide.decoder[l], "decoder level " + std::to_string(l));
    }
    sameDepth(trained.bottleneck, wide.bottleneck, "the bottleneck");
}

// The wider layer `wide` (fresh weights, [out', in', kh, kw]) with the trained layer's weights
// [out, in, kh, kw] in place and 0 from every new input into every trained output.
void embedTrainedWeights(const TensorView& trained, const std::vector<InputRun>& inputs, NamedTensor& wide) {
    const std::int64_t outBefore = trained.shape[0], inBefore = trained.shape[1];
    const std::int64_t inAfter = wide.shape[1];
    const std::int64_t taps = trained.shape[2] * trained.shape[3];
    const auto* weights = static_cast<const float*>(trained.data);
    for (std::int64_t o = 0; o < outBefore; ++o) {
        float* row = wide.floats.data() + o * inAfter * taps;
        std::fill(row, row + inAfter * taps, 0.0f);
        for (const InputRun& run : inputs)
            std::copy(weights + (o * inBefore + run.from) * taps,
                      weights + (o * inBefore + run.from + run.count) * taps, row + run.to * taps);
    }
}

}  // namespace

std::vector<NamedTensor> widened(const Weights& trained, const Weights& fresh) {
    const ModelConfig before = configFromWeights(trained), after = configFromWeights(fresh);
    checkWidenable(before, after, trained.source());
    std::vector<NamedTensor> tensors = copiesOf(fresh);
    auto find = [&](const std::string& name) -> NamedTensor& {
        return tensorNamed(tensors, name, "widen: " + fresh.source());
    };
    for (std::size_t i = 0; i < before.embedWidths.size(); ++i)
        for (const char* part : {".weight", ".bias"}) {
            const std::string name = "embed." + std::to_string(i) + part;
            find(name) = copyOf(trained.tensor(name));
        }
    for (const WidenedConv& conv : widenedConvs(before, after)) {
        embedTrainedWeights(trained.tensor(conv.prefix + ".weight"), conv.inputs, find(conv.prefix + ".weight"));
        const TensorView& bias = trained.tensor(conv.prefix + ".bias");
        const auto* values = static_cast<const float*>(bias.data);
        std::copy(values, values + bias.count, find(conv.prefix + ".bias").floats.begin());
    }
    return tensors;
}

std::vector<NamedTensor> withKernelAdded(const Weights& trained, double bandwidthScale) {
    const ModelConfig before = configFromWeights(trained);
    if (!(bandwidthScale > 0.0) || !std::isfinite(bandwidthScale))
        throw Error("add-kernel: the bandwidth scale must be a positive number, not " + std::to_string(bandwidthScale));
    ModelConfig after = before;
    after.kernels = before.kernels + 1;
    validateConfig(after);
    std::vector<NamedTensor> tensors = copiesOf(trained);
    auto find = [&](const std::string& name) -> NamedTensor& {
        return tensorNamed(tensors, name, "add-kernel: " + trained.source());
    };
    find("config.kernels").ints = {after.kernels};
    const int G = before.kernelChannels(), F = before.affinityFeatures;
    const int lastKernel = (before.kernels - 1) * G, tail = before.kernels * G;
    // Head output rows of the grown model, each taken from a row of the trained head and scaled.
    struct Row {
        int from;
        float scale;
    };
    std::vector<Row> rows;
    for (int r = 0; r < tail; ++r) rows.push_back({r, 1.0f});
    for (int f = 0; f < F; ++f) rows.push_back({lastKernel + f, 1.0f});
    rows.push_back({lastKernel + F, float(bandwidthScale)});
    rows.push_back({lastKernel + F + 1, 1.0f});
    rows.push_back({tail, 1.0f});      // temporal bandwidth
    rows.push_back({tail + 1, 1.0f});  // lambda
    for (const char* part : {".weight", ".bias"}) {
        NamedTensor& head = find(std::string("unet.head") + part);
        const std::size_t perRow = head.floats.size() / std::size_t(before.headChannels());
        std::vector<float> grown;
        grown.reserve(rows.size() * perRow);
        for (const Row& row : rows)
            for (std::size_t i = 0; i < perRow; ++i)
                grown.push_back(head.floats[std::size_t(row.from) * perRow + i] * row.scale);
        head.floats = std::move(grown);
        head.shape[0] = after.headChannels();
    }
    return tensors;
}

namespace {

// The trained tensors with the configuration tensor `name` replaced by the int32 [1] `value`
// (nullopt: left out).
std::vector<NamedTensor> withConfigInteger(const Weights& trained, const std::string& name, std::optional<int> value) {
    std::vector<NamedTensor> tensors;
    for (NamedTensor& tensor : copiesOf(trained))
        if (tensor.name != name) tensors.push_back(std::move(tensor));
    if (value) {
        NamedTensor config;
        config.name = name;
        config.dtype = DType::Int32;
        config.shape = {1};
        config.ints = {*value};
        tensors.push_back(std::move(config));
    }
    return tensors;
}

}  // namespace

std::vector<NamedTensor> withTemporalGain(const Weights& trained, int percent) {
    if (percent < 1 || percent > kMaxTemporalGainPercent)
        throw Error("temporal gain " + std::to_string(percent) + " % is outside 1.." +
                    std::to_string(kMaxTemporalGainPercent));
    return withConfigInteger(trained, "config.temporal_gain_percent",
                             percent == 100 ? std::nullopt : std::optional<int>(percent));
}

std::vector<NamedTensor> withLightRestoration(const Weights& trained, bool on) {
    return withConfigInteger(trained, "config.light_restoration", on ? 1 : 0);
}

}  // namespace affinity::train
