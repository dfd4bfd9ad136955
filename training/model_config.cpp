#include "model_config.h"

#include <algorithm>
#include <utility>

#include "affinity/error.h"
#include "affinity/features.h"
#include "affinity/weights.h"
#include "network/network.h"

namespace affinity::train {
namespace {

std::string str(int value) { return std::to_string(value); }

std::string shapeText(const std::vector<std::int64_t>& shape) {
    std::string text = "[";
    for (std::size_t i = 0; i < shape.size(); ++i) text += (i ? ", " : "") + std::to_string(shape[i]);
    return text + "]";
}

void checkStack(const ConvStackSpec& stack, const std::string& what) {
    if (stack.widths.empty()) throw Error("model config: " + what + " has no convolutions");
    for (int width : stack.widths) {
        if (width < 1) throw Error("model config: " + what + " has a convolution of width " + str(width));
    }
}

void addConv(std::vector<TensorSpec>& specs, const std::string& prefix, int out, int in, int size) {
    specs.push_back({prefix + ".weight", {out, in, size, size}});
    specs.push_back({prefix + ".bias", {out}});
}

// Appends the convolutions of one stack reading `in` channels; returns its output width.
int addStack(std::vector<TensorSpec>& specs, const std::string& prefix, const ConvStackSpec& stack, int in) {
    for (std::size_t j = 0; j < stack.widths.size(); ++j) {
        addConv(specs, prefix + ".conv" + std::to_string(j), stack.widths[j], in, 3);
        in = stack.widths[j];
    }
    return in;
}

// Output widths of `prefix`conv0, conv1, ... as far as they exist.
ConvStackSpec readStack(const Weights& weights, const std::string& prefix) {
    ConvStackSpec stack;
    for (int j = 0;; ++j) {
        const std::string name = prefix + ".conv" + str(j) + ".weight";
        if (!weights.has(name)) break;
        const TensorView& view = weights.tensor(name);
        if (view.shape.empty()) throw Error(weights.source() + ": tensor " + name + " has no dimensions");
        stack.widths.push_back(int(view.shape[0]));
    }
    return stack;
}

int readConfigInt(const Weights& weights, const std::string& name) {
    if (!weights.has(name)) throw Error(weights.source() + ": the configuration tensor " + name + " is missing");
    return weights.integer(name);
}

}  // namespace

void validateConfig(const ModelConfig& config) {
    if (config.embedWidths.empty()) throw Error("model config: the embedding has no layers");
    for (int width : config.embedWidths) {
        if (width < 1) throw Error("model config: an embedding layer has width " + str(width));
    }
    if (config.encoder.empty()) throw Error("model config: the U-Net has no encoder levels");
    if (config.decoder.size() != config.encoder.size()) {
        throw Error("model config: " + str(int(config.encoder.size())) + " encoder levels but " +
                    str(int(config.decoder.size())) + " decoder levels");
    }
    for (std::size_t l = 0; l < config.encoder.size(); ++l) {
        checkStack(config.encoder[l], "encoder level " + std::to_string(l));
        checkStack(config.decoder[l], "decoder level " + std::to_string(l));
    }
    checkStack(config.bottleneck, "the bottleneck");
    // The upper bounds only keep dilations (2^k) and channel counts far from overflow.
    if (config.kernels < 1 || config.kernels > 16) {
        throw Error("model config: kernel count " + str(config.kernels) + " is outside 1..16");
    }
    if (config.affinityFeatures < 1 || config.affinityFeatures > 4096) {
        throw Error("model config: affinity feature count " + str(config.affinityFeatures) + " is outside 1..4096");
    }
    if (config.kernelSize < 1 || config.kernelSize > 63 || config.kernelSize % 2 == 0) {
        throw Error("model config: kernel size " + str(config.kernelSize) + " is not an odd number in 1..63");
    }
}

std::vector<std::string> presetNames() { return {"tiny", "small", "medium", "paper"}; }

ModelConfig presetConfig(const std::string& name) {
    ModelConfig config;
    if (name == "tiny") {
        config.embedWidths = {16, 16};
        config.encoder = {{{16}}, {{24}}};
        config.bottleneck = {{32}};
        config.decoder = {{{16}}, {{24}}};
    } else if (name == "small") {
        config.embedWidths = {32, 32};
        config.encoder = {{{24}}, {{32}}, {{48}}};
        config.bottleneck = {{64}};
        config.decoder = {{{24}}, {{32}}, {{48}}};
    } else if (name == "medium") {
        // small's depths at about 1.4x its widths: the ladder's step above the default, and
        // what `affinity_model_tool widen` grows a trained small model into.
        config.embedWidths = {32, 32};
        config.encoder = {{{32}}, {{48}}, {{64}}};
        config.bottleneck = {{96}};
        config.decoder = {{{32}}, {{48}}, {{64}}};
    } else if (name == "paper") {
        // Encoder 64-64-64-80 and a 96-wide bottleneck as in third-party reimplementations;
        // one convolution per decoder level keeps the full-resolution cost down.
        config.embedWidths = {32, 32, 32};
        config.encoder = {{{64}}, {{64, 64}}, {{64, 64}}, {{80, 80}}};
        config.bottleneck = {{96, 96}};
        config.decoder = {{{64}}, {{64}}, {{64}}, {{80}}};
    } else {
        std::string known;
        for (const std::string& preset : presetNames()) known += (known.empty() ? "" : ", ") + preset;
        throw Error("unknown model preset '" + name + "' (known: " + known + ")");
    }
    return config;
}

std::vector<TensorSpec> parameterSpecs(const ModelConfig& config) {
    validateConfig(config);
    std::vector<TensorSpec> specs;
    int in = kFeatureCount;
    for (std::size_t i = 0; i < config.embedWidths.size(); ++i) {
        const std::string prefix = "embed." + std::to_string(i);
        specs.push_back({prefix + ".weight", {config.embedWidths[i], in}});
        specs.push_back({prefix + ".bias", {config.embedWidths[i]}});
        in = config.embedWidths[i];
    }
    const int levels = int(config.encoder.size());
    std::vector<int> skipWidths;
    in = 2 * config.embeddingChannels();
    for (int l = 0; l < levels; ++l) {
        in = addStack(specs, "unet.enc" + str(l), config.encoder[std::size_t(l)], in);
        skipWidths.push_back(in);
    }
    in = addStack(specs, "unet.bottleneck", config.bottleneck, in);
    for (int l = levels - 1; l >= 0; --l) {
        in = addStack(specs, "unet.dec" + str(l), config.decoder[std::size_t(l)], in + skipWidths[std::size_t(l)]);
    }
    addConv(specs, "unet.head", config.headChannels(), in, 1);
    return specs;
}

std::int64_t parameterCount(const ModelConfig& config) {
    std::int64_t count = 0;
    for (const TensorSpec& spec : parameterSpecs(config)) {
        std::int64_t size = 1;
        for (std::int64_t dim : spec.shape) size *= dim;
        count += size;
    }
    return count;
}

ModelConfig configFromWeights(const Weights& weights) {
    const std::string& source = weights.source();
    const int version = readConfigInt(weights, "config.version");
    if (version != 1) throw Error(source + ": config.version is " + str(version) + ", expected 1");
    ModelConfig config;
    config.kernels = readConfigInt(weights, "config.kernels");
    config.affinityFeatures = readConfigInt(weights, "config.affinity_features");
    config.kernelSize = readConfigInt(weights, "config.kernel_size");
    // Optional switches, absent in files written before they existed: absent reads as off.
    auto flag = [&](const char* name) {
        if (!weights.has(name)) return false;
        const int value = readConfigInt(weights, name);
        if (value != 0 && value != 1) throw Error(source + ": " + name + " is " + str(value) + ", expected 0 or 1");
        return value == 1;
    };
    config.lightRestoration = flag("config.light_restoration");
    if (weights.has("config.temporal_gain_percent")) {
        config.temporalGainPercent = readConfigInt(weights, "config.temporal_gain_percent");
        if (config.temporalGainPercent < 1 || config.temporalGainPercent > kMaxTemporalGainPercent)
            throw Error(source + ": config.temporal_gain_percent is " + str(config.temporalGainPercent) +
                        ", expected 1.." + str(kMaxTemporalGainPercent));
    }
    // Switches of variants that lost and were removed (docs/TRAINING.md, "Tried and lost"): a file
    // that turns one on is refused rather than trained or exported as a different model.
    for (const auto& [name, what] : {std::pair<const char*, const char*>{"config.source_weights", "source weights"},
                                     {"config.emission_lambda", "a separate emission lambda"},
                                     {"config.albedo_demodulation", "albedo demodulation"},
                                     {"config.emission_bypass", "emission bypass"}})
        if (flag(name))
            throw Error(source + ": " + name + " = 1: the option " + what +
                        " was removed (no shipped model used it); this version cannot load the model");

    for (int i = 0;; ++i) {
        const std::string name = "embed." + str(i) + ".weight";
        if (!weights.has(name)) break;
        const TensorView& view = weights.tensor(name);
        if (view.shape.empty()) throw Error(source + ": tensor " + name + " has no dimensions");
        config.embedWidths.push_back(int(view.shape[0]));
    }
    for (int l = 0;; ++l) {
        ConvStackSpec stack = readStack(weights, "unet.enc" + str(l));
        if (stack.widths.empty()) break;
        config.encoder.push_back(std::move(stack));
    }
    config.bottleneck = readStack(weights, "unet.bottleneck");
    for (std::size_t l = 0; l < config.encoder.size(); ++l) {
        config.decoder.push_back(readStack(weights, "unet.dec" + std::to_string(l)));
    }
    try {
        validateConfig(config);
    } catch (const Error& error) {
        throw Error(source + ": " + error.what());
    }

    // Every tensor the structure implies must be there with exactly its shape, and nothing else.
    const std::vector<TensorSpec> specs = parameterSpecs(config);
    for (const TensorSpec& spec : specs) {
        if (!weights.has(spec.name)) throw Error(source + ": tensor " + spec.name + " is missing");
        const TensorView& view = weights.tensor(spec.name);
        if (view.dtype != DType::Float32) throw Error(source + ": tensor " + spec.name + " is not float32");
        if (view.shape != spec.shape) {
            throw Error(source + ": tensor " + spec.name + " has shape " + shapeText(view.shape) +
                        ", the model's structure needs " + shapeText(spec.shape) +
                        " (head outputs P = K (F + 2) + 2 = " + str(config.headChannels()) + ")");
        }
    }
    for (const std::string& name : weights.names()) {
        const bool known = name.rfind("config.", 0) == 0 ||
                           std::any_of(specs.begin(), specs.end(), [&](const TensorSpec& s) { return s.name == name; });
        if (!known) throw Error(source + ": tensor " + name + " is not part of the model");
    }
    return config;
}

FlopCount flopCount(const ModelConfig& config) {
    validateConfig(config);
    FlopCount flops;
    int in = kFeatureCount;
    for (int width : config.embedWidths) {
        flops.embeddingPerSample += 2.0 * in * width;
        in = width;
    }
    // A 3x3 convolution at level l touches 1 / 4^l of the full-resolution pixels.
    auto stackFlops = [](const ConvStackSpec& stack, int input, double scale, int& output) {
        double total = 0;
        for (int width : stack.widths) {
            total += 2.0 * 9.0 * input * width * scale;
            input = width;
        }
        output = input;
        return total;
    };
    const int levels = int(config.encoder.size());
    std::vector<int> skipWidths;
    in = 2 * config.embeddingChannels();
    double scale = 1.0;
    for (int l = 0; l < levels; ++l, scale /= 4.0) {
        flops.unetPerPixel += stackFlops(config.encoder[std::size_t(l)], in, scale, in);
        skipWidths.push_back(in);
    }
    flops.unetPerPixel += stackFlops(config.bottleneck, in, scale, in);
    for (int l = levels - 1; l >= 0; --l) {
        scale *= 4.0;
        const int input = in + skipWidths[std::size_t(l)];
        flops.unetPerPixel += stackFlops(config.decoder[std::size_t(l)], input, scale, in);
    }
    flops.unetPerPixel += 2.0 * in * config.headChannels();

    // A neighbour tap: F differences, squares and sums, the bandwidth product, an exp, a
    // weighted multiply-add per filtered channel and the denominator.
    const int C = ModelConfig::kSignalChannels;
    const double tap = 3.0 * config.affinityFeatures + 4.0 + 2.0 * C;
    const double taps = double(config.kernelSize) * config.kernelSize - 1.0;
    flops.filterPerPixel = config.kernels * (taps * tap + 7.0 + 4.0) + 9.0 * tap;
    // Bilinear warps (8 per channel) of the embedding, radiance, output and features, and the
    // two moving averages (3 per channel).
    const int E = config.embeddingChannels();
    flops.filterPerPixel += 8.0 * (E + 2 * C + config.affinityFeatures) + 3.0 * (E + C);
    return flops;
}

}  // namespace affinity::train
