#include "network/network.h"

#include <set>

#include "affinity/error.h"
#include "affinity/weights.h"

namespace affinity {
namespace {

// Every 3x3 layer without a folded upsampled input runs in the Winograd form (the folded ones
// run their skip part in it): it is faster than the direct form at every width the models use,
// the narrowest least (bench_conv, results/bench_conv_1080p_zen4.txt).
ConvForm formFor(int size, int upsampled) {
    return size == 3 && upsampled == 0 ? ConvForm::Winograd : ConvForm::Direct;
}

class Builder {
public:
    Builder(const Weights& weights, Precision precision) : weights_(weights), precision_(precision) {}

    [[noreturn]] void fail(const std::string& what) const { throw Error("model " + weights_.source() + ": " + what); }

    int config(const std::string& name, int lo, int hi) {
        if (!weights_.has(name)) fail("missing configuration tensor '" + name + "'");
        used_.insert(name);
        int value = weights_.integer(name);
        if (value < lo || value > hi)
            fail("'" + name + "' = " + std::to_string(value) + " is outside " + std::to_string(lo) + ".." +
                 std::to_string(hi));
        return value;
    }

    // An optional 0/1 switch: files written before it existed lack it, which reads as off.
    bool flag(const std::string& name) { return weights_.has(name) && config(name, 0, 1) == 1; }

    // A switch of a variant that lost and was removed (docs/TRAINING.md, "Tried and lost"): off
    // (0 or absent) is the model this code computes; on, the file is refused rather than misread.
    void removedFlag(const std::string& name, const std::string& what) {
        if (flag(name))
            fail(name + " = 1: the option " + what +
                 " was removed (no shipped model used it); this version cannot run the model");
    }

    // A conv "<prefix>.weight" [out, in, size, size] + "<prefix>.bias" [out] whose input count
    // must be `in` (-1: any).
    // `upsampled` > 0: the layer reads that many channels of a coarser level upsampled.
    Conv2d conv(const std::string& prefix, int in, int size, int upsampled = 0) {
        const std::string weightName = prefix + ".weight";
        used_.insert({weightName, prefix + ".bias"});
        const TensorView& w = weights_.tensor(weightName);
        if (w.shape.size() != 4 || w.shape[2] != size || w.shape[3] != size)
            fail("'" + weightName + "' must have shape [out, in, " + std::to_string(size) + ", " +
                 std::to_string(size) + "]");
        const int out = int(w.shape[0]);
        if (in >= 0 && w.shape[1] != in)
            fail("'" + weightName + "' takes " + std::to_string(w.shape[1]) + " input channels but receives " +
                 std::to_string(in));
        const float* bias = weights_.floats(prefix + ".bias", {out});
        parameters_ += std::int64_t(w.count) + out;
        return Conv2d(static_cast<const float*>(w.data), bias, out, int(w.shape[1]), size, defaultConvIsa(), upsampled,
                      formFor(size, upsampled), precision_);
    }

    // Convolutions "<prefix>.conv0", "<prefix>.conv1", ... chained from `in` channels, of which
    // the first conv0 reads `upsampled` upsampled (a decoder level).
    std::vector<Conv2d> block(const std::string& prefix, int in, int upsampled = 0) {
        std::vector<Conv2d> convs;
        for (int j = 0; weights_.has(prefix + ".conv" + std::to_string(j) + ".weight"); ++j) {
            convs.push_back(conv(prefix + ".conv" + std::to_string(j), in, 3, j == 0 ? upsampled : 0));
            in = convs.back().outChannels();
        }
        if (convs.empty()) fail("missing '" + prefix + ".conv0.weight'");
        return convs;
    }

    std::vector<DenseLayer> embedding() {
        std::vector<DenseLayer> layers;
        int in = kFeatureChannels;
        for (int i = 0; weights_.has("embed." + std::to_string(i) + ".weight"); ++i) {
            const std::string prefix = "embed." + std::to_string(i);
            used_.insert({prefix + ".weight", prefix + ".bias"});
            const TensorView& w = weights_.tensor(prefix + ".weight");
            if (w.shape.size() != 2 || w.shape[1] != in)
                fail("'" + prefix + ".weight' must have shape [out, " + std::to_string(in) + "]");
            DenseLayer layer;
            layer.in = in;
            layer.out = int(w.shape[0]);
            const float* weight = weights_.floats(prefix + ".weight", {layer.out, in});
            const float* bias = weights_.floats(prefix + ".bias", {layer.out});
            layer.weight.assign(weight, weight + std::size_t(layer.out) * in);
            layer.bias.assign(bias, bias + layer.out);
            parameters_ += std::int64_t(layer.weight.size() + layer.bias.size());
            in = layer.out;
            layers.push_back(std::move(layer));
        }
        if (layers.empty()) fail("missing 'embed.0.weight'");
        return layers;
    }

    std::int64_t parameters() const { return parameters_; }

    // Every tensor must be part of the network: a stray one means a mismatched exporter.
    void requireAllUsed() const {
        for (const std::string& name : weights_.names())
            if (!used_.count(name)) fail("unexpected tensor '" + name + "'");
    }

    static constexpr int kFeatureChannels = 18;

private:
    const Weights& weights_;
    Precision precision_;
    std::int64_t parameters_ = 0;
    std::set<std::string> used_;
};

}  // namespace

Network buildNetwork(const Weights& weights, Precision precision) {
    precision = resolvePrecision(precision);
    if (precision == Precision::BFloat16 && !bfloat16Supported())
        throw Error("model " + weights.source() +
                    ": bfloat16 precision needs a CPU with AVX512-BF16 (and an x86-64 "
                    "build with AVX-512 kernels); this one has none: use fp32 (or auto, which picks it)");
    Builder b(weights, precision);
    Network n;
    n.source = weights.source();
    n.precision = precision;
    const int version = b.config("config.version", 1, 1000);
    if (version != 1) b.fail("model version " + std::to_string(version) + " is not supported (expected 1)");
    n.kernels = b.config("config.kernels", 1, 8);
    n.affinityFeatures = b.config("config.affinity_features", 1, 64);
    n.tapSize = b.config("config.kernel_size", 1, 15);
    if (n.tapSize % 2 == 0) b.fail("config.kernel_size must be odd");
    n.lightRestoration = b.flag("config.light_restoration");
    if (weights.has("config.temporal_gain_percent"))
        n.temporalGain = float(b.config("config.temporal_gain_percent", 1, kMaxTemporalGainPercent)) / 100.0f;
    b.removedFlag("config.source_weights", "source weights");
    b.removedFlag("config.emission_lambda", "a separate emission lambda");
    b.removedFlag("config.albedo_demodulation", "albedo demodulation");
    b.removedFlag("config.emission_bypass", "emission bypass");

    std::vector<DenseLayer> dense = b.embedding();
    n.embeddingWidths.push_back(dense.front().in);
    for (const DenseLayer& layer : dense) n.embeddingWidths.push_back(layer.out);
    n.embedding.emplace(std::move(dense), precision);
    const int embeddingChannels = n.embedding->outChannels();

    int channels = 2 * embeddingChannels;  // concat(e_t, warped history)
    std::vector<int> skipChannels;
    for (int level = 0; weights.has("unet.enc" + std::to_string(level) + ".conv0.weight"); ++level) {
        n.encoder.push_back(b.block("unet.enc" + std::to_string(level), channels));
        channels = n.encoder.back().back().outChannels();
        skipChannels.push_back(channels);
    }
    if (n.encoder.empty()) b.fail("missing 'unet.enc0.conv0.weight'");
    n.bottleneck = b.block("unet.bottleneck", channels);
    channels = n.bottleneck.back().outChannels();
    n.decoder.resize(n.encoder.size());
    for (int level = int(n.encoder.size()) - 1; level >= 0; --level) {
        n.decoder[level] = b.block("unet.dec" + std::to_string(level), channels + skipChannels[level], channels);
        channels = n.decoder[level].back().outChannels();
    }
    n.head.emplace(b.conv("unet.head", channels, 1));
    if (n.head->outChannels() != n.headChannels())
        b.fail("'unet.head.weight' has " + std::to_string(n.head->outChannels()) +
               " outputs but K = " + std::to_string(n.kernels) + ", F = " + std::to_string(n.affinityFeatures) +
               " needs " + std::to_string(n.headChannels()));
    n.parameterCount = b.parameters();
    b.requireAllUsed();
    return n;
}

}  // namespace affinity
