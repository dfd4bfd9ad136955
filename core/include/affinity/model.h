#pragma once
// A denoising model: the network's weights and structure (docs/MODEL.md), validated at load.
// Models of any size load without code changes: layer counts and widths come from the file.
#include <cstdint>
#include <memory>
#include <string>

#include "affinity/precision.h"

namespace affinity {

class Weights;
struct Network;

class Model {
public:
    // The default model compiled into the library. `precision` (affinity/precision.h): Auto,
    // the default, computes in bfloat16 where the CPU has AVX512-BF16 and in FP32 elsewhere;
    // BFloat16 throws affinity::Error where !bfloat16Supported().
    static Model builtIn(Precision precision = Precision::Auto);
    // Throws affinity::Error naming the file and what is wrong or inconsistent in it.
    static Model fromFile(const std::string& path, Precision precision = Precision::Auto);
    static Model fromWeights(const Weights& weights, Precision precision = Precision::Auto);

    const std::string& source() const;
    int kernels() const;           // K
    int affinityFeatures() const;  // F
    int tapSize() const;           // T
    // Whether denoising restores light after the kernels (docs/MODEL.md section 10); set in the
    // weights file (config.light_restoration), off for files without it.
    bool lightRestoration() const;
    int embeddingChannels() const;  // E
    std::int64_t parameterCount() const;
    Precision precision() const;  // what it computes in: Float32 or BFloat16, never Auto
    // Multiply-adds x 2 per pixel of the per-pixel network at `spp` samples per pixel.
    double flopsPerPixel(int spp) const;

    const Network& network() const { return *network_; }

private:
    explicit Model(std::shared_ptr<const Network> network) : network_(std::move(network)) {}
    std::shared_ptr<const Network> network_;
};

}  // namespace affinity
