#include "model_surgery.h"

#include <algorithm>
#include <cmath>
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

// Appends a copy of the last output channel of a [P, ...] tensor (lambda is the head's last).
void repeatLastOutput(NamedTensor& tensor) {
    const std::size_t perOutput = tensor.floats.size() / std::size_t(tensor.shape[0]);
    const std::vector<float> last(tensor.floats.end() - std::ptrdiff_t(perOutput), tensor.floats.end());
    tensor.floats.insert(tensor.floats.end(), last.begin(), last.end());
    tensor.shape[0] += 1;
}

// Rows `kept` of a tensor whose first dimension is the output channel.
void keepOutputs(NamedTensor& tensor, const std::vector<int>& kept) {
    const std::size_t perRow = tensor.floats.size() / std::size_t(tensor.shape[0]);
    std::vector<float> rows;
    for (int c : kept)
        rows.insert(rows.end(), tensor.floats.begin() + std::ptrdiff_t(std::size_t(c) * perRow),
                    tensor.floats.begin() + std::ptrdiff_t(std::size_t(c + 1) * perRow));
    tensor.floats = std::move(rows);
    tensor.shape[0] = std::int64_t(kept.size());
}

// A [O, I, kh, kw] weight with its inputs [offset, offset + width) cut to offset + `kept`.
void keepInputs(NamedTensor& tensor, int offset, int width, const std::vector<int>& kept) {
    const std::int64_t outputs = tensor.shape[0], inputs = tensor.shape[1], taps = tensor.shape[2] * tensor.shape[3];
    std::vector<std::int64_t> order;
    for (std::int64_t i = 0; i < offset; ++i) order.push_back(i);
    for (int c : kept) order.push_back(offset + c);
    for (std::int64_t i = offset + width; i < inputs; ++i) order.push_back(i);
    std::vector<float> narrowed;
    for (std::int64_t o = 0; o < outputs; ++o)
        for (std::int64_t i : order) {
            const auto from = tensor.floats.begin() + std::ptrdiff_t((o * inputs + i) * taps);
            narrowed.insert(narrowed.end(), from, from + std::ptrdiff_t(taps));
        }
    tensor.floats = std::move(narrowed);
    tensor.shape[1] = std::int64_t(order.size());
}

// Sum of squares of a [O, I, kh, kw] tensor's weights on output `o` (all inputs) or on input `i`
// (all outputs).
double outputEnergy(const TensorView& weight, std::int64_t o) {
    const std::int64_t perOutput = weight.shape[1] * weight.shape[2] * weight.shape[3];
    const auto* w = static_cast<const float*>(weight.data) + o * perOutput;
    double sum = 0.0;
    for (std::int64_t k = 0; k < perOutput; ++k) sum += double(w[k]) * double(w[k]);
    return sum;
}
double inputEnergy(const TensorView& weight, std::int64_t i) {
    const std::int64_t inputs = weight.shape[1], taps = weight.shape[2] * weight.shape[3];
    const auto* w = static_cast<const float*>(weight.data);
    double sum = 0.0;
    for (std::int64_t o = 0; o < weight.shape[0]; ++o)
        for (std::int64_t t = 0; t < taps; ++t) {
            const double v = w[(o * inputs + i) * taps + t];
            sum += v * v;
        }
    return sum;
}

// The indices of the `count` largest scores, in increasing order (ties: the lower index first).
std::vector<int> mostImportant(const std::vector<double>& scores, int count) {
    std::vector<int> order(scores.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = int(i);
    std::stable_sort(order.begin(), order.end(),
                     [&](int a, int b) { return scores[std::size_t(a)] > scores[std::size_t(b)]; });
    order.resize(std::size_t(count));
    std::sort(order.begin(), order.end());
    return order;
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

std::vector<NamedTensor> withNarrowerEmbedding(const Weights& trained, int channels) {
    const ModelConfig config = configFromWeights(trained);
    const int E = config.embeddingChannels();
    if (channels < 1 || channels > E)
        throw Error("narrow-embedding: " + std::to_string(channels) + " channels is outside 1.." + std::to_string(E) +
                    " (" + trained.source() + " has E = " + std::to_string(E) + ")");
    const std::string lastEmbed = "embed." + std::to_string(config.embedWidths.size() - 1);
    const TensorView& first = trained.tensor("unet.enc0.conv0.weight");  // [out, 2E, 3, 3]
    std::vector<double> weight;
    for (int c = 0; c < E; ++c) weight.push_back(inputEnergy(first, c) + inputEnergy(first, E + c));
    const std::vector<int> kept = mostImportant(weight, channels);

    std::vector<NamedTensor> tensors;
    for (const std::string& name : trained.names()) {
        tensors.push_back(copyOf(trained.tensor(name)));
        NamedTensor& tensor = tensors.back();
        if (name == lastEmbed + ".weight" || name == lastEmbed + ".bias") keepOutputs(tensor, kept);
        if (name == "unet.enc0.conv0.weight") {
            keepInputs(tensor, E, E, kept);  // the history part first, so that the current part's offset holds
            keepInputs(tensor, 0, E, kept);
        }
    }
    return tensors;
}

namespace {

// A layer that reads a narrowed convolution's output: where those channels start among its inputs.
struct Reader {
    std::string prefix;
    int offset = 0;
};

// A convolution of the narrowed level, the layers that read its output, and the outputs it keeps.
struct NarrowedConv {
    std::string prefix;
    int width = 0;
    std::vector<Reader> readers;
    std::vector<int> kept;
};

std::string convName(const std::string& stack, std::size_t j) { return stack + ".conv" + std::to_string(j); }

// Level `level`'s convolutions and their readers (docs/MODEL.md section 4): within a stack the
// next convolution; the encoder's last is read by the next level (or the bottleneck) and, as the
// skip connection, by the same level's decoder after the coarser level's channels; the decoder's
// last by the finer level's decoder (coarse part first) or, at level 0, the head.
std::vector<NarrowedConv> levelConvs(const ModelConfig& config, int level) {
    const auto l = std::size_t(level);
    const bool deepest = l + 1 == config.encoder.size();
    const std::string encoder = "unet.enc" + std::to_string(level), decoder = "unet.dec" + std::to_string(level);
    std::vector<NarrowedConv> convs;
    const std::vector<int>& encoderWidths = config.encoder[l].widths;
    for (std::size_t j = 0; j < encoderWidths.size(); ++j) {
        NarrowedConv conv{convName(encoder, j), encoderWidths[j], {}, {}};
        if (j + 1 < encoderWidths.size()) {
            conv.readers = {{convName(encoder, j + 1), 0}};
        } else {
            const std::string next = deepest ? "unet.bottleneck" : "unet.enc" + std::to_string(level + 1);
            const int coarse = deepest ? config.bottleneck.outWidth() : config.decoder[l + 1].outWidth();
            conv.readers = {{convName(next, 0), 0}, {convName(decoder, 0), coarse}};
        }
        convs.push_back(conv);
    }
    const std::vector<int>& decoderWidths = config.decoder[l].widths;
    for (std::size_t j = 0; j < decoderWidths.size(); ++j) {
        NarrowedConv conv{convName(decoder, j), decoderWidths[j], {}, {}};
        if (j + 1 < decoderWidths.size())
            conv.readers = {{convName(decoder, j + 1), 0}};
        else
            conv.readers = {{level == 0 ? "unet.head" : convName("unet.dec" + std::to_string(level - 1), 0), 0}};
        convs.push_back(conv);
    }
    return convs;
}

}  // namespace

std::vector<NamedTensor> withNarrowerLevel(const Weights& trained, int level, int channels) {
    const ModelConfig config = configFromWeights(trained);
    const int levels = int(config.encoder.size());
    if (level < 0 || level >= levels)
        throw Error("narrow-level: " + trained.source() + " has no U-Net level " + std::to_string(level) +
                    " (levels 0.." + std::to_string(levels - 1) + ")");
    std::vector<NarrowedConv> convs = levelConvs(config, level);
    for (NarrowedConv& conv : convs) {
        if (channels < 1 || channels > conv.width)
            throw Error("narrow-level: " + std::to_string(channels) + " channels is outside 1.." +
                        std::to_string(conv.width) + " (" + conv.prefix + " of " + trained.source() + ")");
        const TensorView& weight = trained.tensor(conv.prefix + ".weight");
        const auto* bias = static_cast<const float*>(trained.tensor(conv.prefix + ".bias").data);
        std::vector<double> importance;
        for (int c = 0; c < conv.width; ++c) {
            double read = 0.0;
            for (const Reader& reader : conv.readers)
                read += inputEnergy(trained.tensor(reader.prefix + ".weight"), reader.offset + c);
            const double made = outputEnergy(weight, c) + double(bias[c]) * double(bias[c]);
            importance.push_back(std::sqrt(made * read));
        }
        conv.kept = mostImportant(importance, channels);
    }
    std::vector<NamedTensor> tensors = copiesOf(trained);
    auto find = [&](const std::string& name) -> NamedTensor& {
        return tensorNamed(tensors, name, "narrow-level: " + trained.source());
    };
    for (const NarrowedConv& conv : convs) {
        keepOutputs(find(conv.prefix + ".weight"), conv.kept);
        keepOutputs(find(conv.prefix + ".bias"), conv.kept);
    }
    // Inputs last, and a layer's later input runs first so that earlier offsets still hold.
    std::vector<std::pair<Reader, const NarrowedConv*>> reads;
    for (const NarrowedConv& conv : convs)
        for (const Reader& reader : conv.readers) reads.push_back({reader, &conv});
    std::stable_sort(reads.begin(), reads.end(),
                     [](const auto& a, const auto& b) { return a.first.offset > b.first.offset; });
    for (const auto& [reader, conv] : reads)
        keepInputs(find(reader.prefix + ".weight"), reader.offset, conv->width, conv->kept);
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
