#pragma once
// Random models of a chosen shape for tests, built through the training-side writer, and small
// random frame sequences with consistent motion.
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "affinity/frame.h"
#include "affinity/weights.h"
#include "train/weights_writer.h"

namespace affinity::test {

struct ModelShape {
    std::vector<int> embedding{16, 8};  // widths after the 18 inputs; last = E
    std::vector<int> encoder{8, 12};    // one conv per level
    int bottleneck = 16;
    int kernels = 3, affinityFeatures = 4, tapSize = 5;
};

inline std::vector<train::NamedTensor> randomModelTensors(const ModelShape& shape, unsigned seed,
                                                          float headBiasLambda = 0.0f, float headBiasTemporal = 0.0f) {
    std::mt19937 rng(seed);
    std::vector<train::NamedTensor> tensors;
    auto add = [&](const std::string& name, std::vector<std::int64_t> dims, int fanIn) {
        train::NamedTensor t{name, DType::Float32, dims, {}, {}};
        std::size_t count = 1;
        for (auto d : dims) count *= std::size_t(d);
        std::uniform_real_distribution<float> u(-1.0f, 1.0f);
        const float scale = 1.5f / std::sqrt(float(fanIn));
        for (std::size_t i = 0; i < count; ++i) t.floats.push_back(u(rng) * scale);
        tensors.push_back(std::move(t));
    };
    auto config = [&](const std::string& name, int value) {
        tensors.push_back({name, DType::Int32, {1}, {}, {value}});
    };
    config("config.version", 1);
    config("config.kernels", shape.kernels);
    config("config.affinity_features", shape.affinityFeatures);
    config("config.kernel_size", shape.tapSize);
    int in = 18;
    for (std::size_t i = 0; i < shape.embedding.size(); ++i) {
        add("embed." + std::to_string(i) + ".weight", {shape.embedding[i], in}, in);
        add("embed." + std::to_string(i) + ".bias", {shape.embedding[i]}, in);
        in = shape.embedding[i];
    }
    in *= 2;
    std::vector<int> skips;
    for (std::size_t l = 0; l < shape.encoder.size(); ++l) {
        const std::string p = "unet.enc" + std::to_string(l) + ".conv0";
        add(p + ".weight", {shape.encoder[l], in, 3, 3}, 9 * in);
        add(p + ".bias", {shape.encoder[l]}, 9 * in);
        in = shape.encoder[l];
        skips.push_back(in);
    }
    add("unet.bottleneck.conv0.weight", {shape.bottleneck, in, 3, 3}, 9 * in);
    add("unet.bottleneck.conv0.bias", {shape.bottleneck}, 9 * in);
    in = shape.bottleneck;
    for (std::size_t l = shape.encoder.size(); l-- > 0;) {
        const std::string p = "unet.dec" + std::to_string(l) + ".conv0";
        const int inputs = in + skips[l];
        add(p + ".weight", {shape.encoder[l], inputs, 3, 3}, 9 * inputs);
        add(p + ".bias", {shape.encoder[l]}, 9 * inputs);
        in = shape.encoder[l];
    }
    const int lambda = shape.kernels * (shape.affinityFeatures + 2) + 1;
    const int head = lambda + 1;
    add("unet.head.weight", {head, in, 1, 1}, in);
    add("unet.head.bias", {head}, in);
    tensors.back().floats[std::size_t(lambda - 1)] += headBiasTemporal;
    tensors.back().floats[std::size_t(lambda)] += headBiasLambda;
    return tensors;
}

inline Weights randomWeights(const ModelShape& shape, unsigned seed, float headBiasLambda = 0.0f,
                             float headBiasTemporal = 0.0f) {
    std::vector<std::uint8_t> bytes =
        train::serializeWeights(randomModelTensors(shape, seed, headBiasLambda, headBiasTemporal));
    return Weights::fromMemory(bytes.data(), bytes.size(), "random model " + std::to_string(seed));
}

// A random sequence: plausible features, motion of about a pixel, most pixels valid.
inline std::vector<SampleFrame> randomSequence(int frames, int width, int height, int spp, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    std::vector<SampleFrame> sequence;
    for (int t = 0; t < frames; ++t) {
        SampleFrame frame(width, height, spp, true);
        frame.info.frameIndex = t;
        frame.info.worldToCamera = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -5, 0, 0, 0, 1};
        for (int y = 0; y < height; ++y)
            for (int x = 0; x < width; ++x) {
                for (int s = 0; s < spp; ++s) {
                    float* f = frame.sample(x, y, s);
                    for (int c = 0; c < 6; ++c) f[c] = u(rng) < 0.05f ? 20.0f * u(rng) : u(rng);
                    float nx = u(rng) - 0.5f, ny = u(rng) - 0.5f, nz = 1.0f;
                    float n = std::sqrt(nx * nx + ny * ny + nz * nz);
                    f[6] = nx / n, f[7] = ny / n, f[8] = nz / n;
                    f[9] = 2.0f + 3.0f * u(rng);
                    for (int c = 10; c < 13; ++c) f[c] = u(rng);
                    f[13] = u(rng);
                    for (int c = 14; c < 18; ++c) f[c] = u(rng) < 0.2f ? 1.0f : 0.0f;
                }
                frame.motion(x, y)[0] = 2.0f * u(rng) - 1.0f;
                frame.motion(x, y)[1] = 2.0f * u(rng) - 1.0f;
                frame.valid(x, y) = (t > 0 && u(rng) < 0.8f) ? 1.0f : 0.0f;
                for (int c = 0; c < 3; ++c) frame.reference(x, y)[c] = u(rng);
            }
        sequence.push_back(std::move(frame));
    }
    return sequence;
}

}  // namespace affinity::test
