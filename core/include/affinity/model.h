#pragma once
// A denoising model: the network's weights and structure (docs/MODEL.md), validated at load.
// Models of any size load without code changes: layer counts and widths come from the file.
#include <cstdint>
#include <memory>
#include <string>

namespace affinity {

class Weights;
struct Network;

class Model {
public:
    // The default model compiled into the library.
    static Model builtIn();
    // Throws affinity::Error naming the file and what is wrong or inconsistent in it.
    static Model fromFile(const std::string& path);
    static Model fromWeights(const Weights& weights);

    const std::string& source() const;
    int kernels() const;           // K
    int affinityFeatures() const;  // F
    int tapSize() const;           // T
    int embeddingChannels() const; // E
    std::int64_t parameterCount() const;
    // Multiply-adds x 2 per pixel of the per-pixel network at `spp` samples per pixel.
    double flopsPerPixel(int spp) const;

    const Network& network() const { return *network_; }

private:
    explicit Model(std::shared_ptr<const Network> network) : network_(std::move(network)) {}
    std::shared_ptr<const Network> network_;
};

}  // namespace affinity
