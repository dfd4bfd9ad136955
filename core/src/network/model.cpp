#include "affinity/model.h"

#include "affinity/weights.h"
#include "network/network.h"

// The default model's bytes, generated at build time from models/default.affw.
extern "C" const unsigned char affinity_default_model[];
extern "C" const unsigned long affinity_default_model_size;

namespace affinity {

Model Model::builtIn(Precision precision) {
    auto load = [](Precision p) {
        return fromWeights(
            Weights::fromMemory(affinity_default_model, affinity_default_model_size, "built-in default model"), p);
    };
    if (resolvePrecision(precision) == Precision::BFloat16) {
        static const Model model = load(Precision::BFloat16);
        return model;
    }
    static const Model model = load(Precision::Float32);
    return model;
}

Model Model::fromFile(const std::string& path, Precision precision) {
    return fromWeights(Weights::fromFile(path), precision);
}

Model Model::fromWeights(const Weights& weights, Precision precision) {
    return Model(std::make_shared<const Network>(buildNetwork(weights, resolvePrecision(precision))));
}

const std::string& Model::source() const { return network_->source; }
int Model::kernels() const { return network_->kernels; }
int Model::affinityFeatures() const { return network_->affinityFeatures; }
int Model::tapSize() const { return network_->tapSize; }
bool Model::lightRestoration() const { return network_->lightRestoration; }
int Model::embeddingChannels() const { return network_->embedding->outChannels(); }
std::int64_t Model::parameterCount() const { return network_->parameterCount; }
Precision Model::precision() const { return network_->precision; }

double Model::flopsPerPixel(int spp) const {
    const Network& n = *network_;
    double flops = 0.0;
    for (std::size_t i = 1; i < n.embeddingWidths.size(); ++i)
        flops += 2.0 * n.embeddingWidths[i - 1] * n.embeddingWidths[i] * spp;
    auto convs = [&](const std::vector<Conv2d>& block, double scale) {
        for (const Conv2d& c : block) flops += 2.0 * c.size() * c.size() * c.inChannels() * c.outChannels() * scale;
    };
    double scale = 1.0;
    for (std::size_t level = 0; level < n.encoder.size(); ++level, scale /= 4.0) {
        convs(n.encoder[level], scale);
        convs(n.decoder[level], scale);
    }
    convs(n.bottleneck, scale);
    flops += 2.0 * n.head->inChannels() * n.head->outChannels();
    return flops;
}

}  // namespace affinity
