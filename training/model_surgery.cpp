#include "model_surgery.h"

#include <algorithm>
#include <string>

#include "affinity/error.h"
#include "model_config.h"

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

// Appends a copy of the last output channel of a [P, ...] tensor (lambda is the head's last).
void repeatLastOutput(NamedTensor& tensor) {
    const std::size_t perOutput = tensor.floats.size() / std::size_t(tensor.shape[0]);
    const std::vector<float> last(tensor.floats.end() - std::ptrdiff_t(perOutput), tensor.floats.end());
    tensor.floats.insert(tensor.floats.end(), last.begin(), last.end());
    tensor.shape[0] += 1;
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
    if (trained.albedoDemodulation != wide.albedoDemodulation || trained.sourceWeights != wide.sourceWeights ||
        trained.emissionBypass != wide.emissionBypass || trained.emissionLambda != wide.emissionLambda)
        fail("the model options differ");
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
            std::copy(weights + (o * inBefore + run.from) * taps, weights + (o * inBefore + run.from + run.count) * taps,
                      row + run.to * taps);
    }
}

}  // namespace

std::vector<NamedTensor> widened(const Weights& trained, const Weights& fresh) {
    const ModelConfig before = configFromWeights(trained), after = configFromWeights(fresh);
    checkWidenable(before, after, trained.source());
    std::vector<NamedTensor> tensors;
    for (const std::string& name : fresh.names()) tensors.push_back(copyOf(fresh.tensor(name)));
    auto find = [&](const std::string& name) -> NamedTensor& {
        for (NamedTensor& tensor : tensors)
            if (tensor.name == name) return tensor;
        throw Error("widen: " + fresh.source() + " has no tensor " + name);
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

std::vector<NamedTensor> withNarrowerEmbedding(const Weights& trained, int channels) {
    const ModelConfig config = configFromWeights(trained);
    const int E = config.embeddingChannels();
    if (channels < 1 || channels > E)
        throw Error("narrow-embedding: " + std::to_string(channels) + " channels is outside 1.." + std::to_string(E) +
                    " (" + trained.source() + " has E = " + std::to_string(E) + ")");
    const std::string lastEmbed = "embed." + std::to_string(config.embedWidths.size() - 1);
    const TensorView& first = trained.tensor("unet.enc0.conv0.weight");  // [out, 2E, 3, 3]
    const std::int64_t out = first.shape[0], taps = first.shape[2] * first.shape[3];
    const auto* w = static_cast<const float*>(first.data);
    std::vector<std::pair<double, int>> weight(std::size_t(E), {0.0, 0});
    for (int c = 0; c < E; ++c) {
        weight[std::size_t(c)].second = c;
        for (std::int64_t o = 0; o < out; ++o)
            for (int part : {c, E + c})
                for (std::int64_t t = 0; t < taps; ++t) {
                    const double v = w[(o * 2 * E + part) * taps + t];
                    weight[std::size_t(c)].first += v * v;
                }
    }
    std::stable_sort(weight.begin(), weight.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
    std::vector<int> kept;
    for (int i = 0; i < channels; ++i) kept.push_back(weight[std::size_t(i)].second);
    std::sort(kept.begin(), kept.end());

    // Rows (output channels) `kept` of a [E, ...] tensor.
    auto keepRows = [&](NamedTensor& tensor) {
        const std::size_t perRow = tensor.floats.size() / std::size_t(tensor.shape[0]);
        std::vector<float> rows;
        for (int c : kept)
            rows.insert(rows.end(), tensor.floats.begin() + std::ptrdiff_t(std::size_t(c) * perRow),
                        tensor.floats.begin() + std::ptrdiff_t(std::size_t(c + 1) * perRow));
        tensor.floats = std::move(rows);
        tensor.shape[0] = channels;
    };
    std::vector<NamedTensor> tensors;
    for (const std::string& name : trained.names()) {
        tensors.push_back(copyOf(trained.tensor(name)));
        NamedTensor& tensor = tensors.back();
        if (name == lastEmbed + ".weight" || name == lastEmbed + ".bias") keepRows(tensor);
        if (name == "unet.enc0.conv0.weight") {
            std::vector<float> narrowed;
            for (std::int64_t o = 0; o < out; ++o)
                for (int part : {0, E})
                    for (int c : kept) {
                        const float* from = w + (o * 2 * E + part + c) * taps;
                        narrowed.insert(narrowed.end(), from, from + taps);
                    }
            tensor.floats = std::move(narrowed);
            tensor.shape[1] = 2 * channels;
        }
    }
    return tensors;
}

std::vector<NamedTensor> withEmissionLambda(const Weights& weights) {
    const ModelConfig config = configFromWeights(weights);  // also checks the head's shape
    if (!config.emissionBypass)
        throw Error(weights.source() + ": an emission lambda needs a model with emission bypass");
    if (config.emissionLambda) throw Error(weights.source() + ": the model already has an emission lambda");
    std::vector<NamedTensor> tensors;
    for (const std::string& name : weights.names()) {
        tensors.push_back(copyOf(weights.tensor(name)));
        if (name == "unet.head.weight" || name == "unet.head.bias") repeatLastOutput(tensors.back());
    }
    tensors.push_back({"config.emission_lambda", DType::Int32, {1}, {}, {1}});
    return tensors;
}

}  // namespace affinity::train
