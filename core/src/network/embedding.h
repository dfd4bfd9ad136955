#pragma once
// The per-sample embedding network of docs/MODEL.md section 2 and the input transform of
// section 1: every sample's 18 features through a small MLP, averaged per pixel.
#include <functional>
#include <vector>

#include "affinity/features.h"
#include "affinity/precision.h"
#include "kernels/bf16_gemm.h"
#include "kernels/conv_kernel.h"
#include "kernels/feature_map.h"

namespace affinity {

struct DenseLayer {
    int in = 0, out = 0;
    std::vector<float> weight;  // [out][in], torch layout
    std::vector<float> bias;    // [out]
};

// A frame's per-sample features ([y][x][s][feature]) in bands of rows: rows
// [i * bandRows, (i + 1) * bandRows) at bands[i], the last band possibly shorter. One band holds
// a frame that is one buffer; a frame lent in bands (Denoiser::sampleBands) has several.
struct SampleBands {
    SampleBands() = default;
    SampleBands(const float* samples, int frameHeight, int frameWidth, int samplesPerPixel)
        : bands{samples}, bandRows(frameHeight), width(frameWidth), spp(samplesPerPixel) {}
    std::vector<const float*> bands;
    int bandRows = 0, width = 0, spp = 0;

    std::size_t pixelValues() const { return std::size_t(spp) * kFeatureCount; }
    const float* row(int y) const {
        return bands[std::size_t(y / bandRows)] + std::size_t(y % bandRows) * std::size_t(width) * pixelValues();
    }
    // The samples of `count` consecutive pixels from pixel index `first` (row-major): where they
    // are if one band holds them, else copied into `gather` (count x pixelValues() floats).
    const float* pixels(long long first, int count, float* gather) const;
};

// The per-frame scales of the input transform (docs/MODEL.md section 1): depth times `depth`,
// radiance times `exposure` before log(1 + r). From a float: a depth scale at exposure 1.
struct InputScales {
    InputScales(float depthScale, float exposureScale = 1.0f) : depth(depthScale), exposure(exposureScale) {}
    float depth;
    float exposure;
};

class Embedding {
public:
    // Validates the chain: at least one layer, the first takes kFeatureCount inputs, each
    // takes what the previous gives, weight and bias sizes match (throws affinity::Error).
    // With Precision::BFloat16 every layer takes its products in bfloat16 (bf16_gemm.h), unless
    // one has an odd input count (then all stay FP32).
    explicit Embedding(std::vector<DenseLayer> layers, Precision precision = Precision::Float32);
    int outChannels() const;

    // Per-pixel sums over the samples that apply() and accumulate() can write beside the
    // embedding, without a second pass over the samples, added in sample order, of sanitised
    // values (non-finite or negative read as 0): diffuse RGB, specular RGB, the square of each
    // sample's luminance (diffuse + specular), from which the input's noise is judged, and how
    // many samples saw an emitter first (the `emissive` flag above 0.5), which the peak guard
    // reads.
    static constexpr int kSampleSumChannels = 8;
    static constexpr int kSumDiffuse = 0, kSumSpecular = 3, kSumLuminanceSquares = 6, kSumEmissive = 7;

    // samples: [pixels][spp][kFeatureCount] raw features (frame layout); scales from
    // section 1. Writes the per-pixel mean embedding to `output` (height x width x E).
    // Non-finite or negative radiance is treated as 0; returns how many radiance values were.
    // With `sampleSums`, also writes the sums above (height x width x kSampleSumChannels).
    // Multithreaded; the result does not depend on the thread count.
    long long apply(const float* samples, int height, int width, int spp, InputScales scales, FeatureMap& output,
                    FeatureMap* sampleSums = nullptr) const {
        return apply(SampleBands(samples, height, width, spp), height, scales, output, sampleSums);
    }
    // The same on samples in bands of rows: the same result bit for bit.
    long long apply(const SampleBands& samples, int height, InputScales scales, FeatureMap& output,
                    FeatureMap* sampleSums = nullptr) const;
    // The same with the sums handed chunk by chunk to sink(first pixel, pixel count, the chunk's
    // sums, kSampleSumChannels per pixel), called from the worker threads, so that they need
    // not be kept for the whole frame.
    using SumsSink = std::function<void(long long firstPixel, int count, const float* sums)>;
    long long apply(const SampleBands& samples, int height, InputScales scales, FeatureMap& output,
                    const SumsSink& sink) const;

    // apply() in two steps, for samples that arrive in batches: accumulate() adds each sample's
    // output of all layers but the last to `hiddenSum` (height x width x hiddenChannels(),
    // started afresh when `first`; likewise the sample sums), finish() applies the last layer
    // to hiddenSum / spp. Batches
    // added in sample order give apply()'s result bit for bit (the last layer is linear, so the
    // mean can be taken before it). accumulate() returns the bad radiance count as apply().
    long long accumulate(const float* samples, int height, int width, int spp, InputScales scales,
                         FeatureMap& hiddenSum, bool first, FeatureMap* sampleSums = nullptr) const;
    // `output` may be `hiddenSum` itself when outChannels() == hiddenChannels(): the embedding
    // then takes the sums' memory instead of a second map (each chunk is read before written).
    void finish(const FeatureMap& hiddenSum, int spp, FeatureMap& output) const;
    int hiddenChannels() const;

private:
    // Runs all layers but the last on the samples, chunk by chunk in parallel, and calls
    // consume(firstPixel, pixelCount, hidden, scratch) per chunk with hidden = the chunk's
    // per-sample outputs ([pixel][sample][hiddenChannels()]) and a per-thread scratch buffer of
    // chunkPixels x max(hiddenChannels(), kFeatureCount) floats.
    // When sampleSums is given, the chunk's sums go into it (started at 0 if firstSums); else
    // when sink is, to it.
    template <class Consume>
    long long forEachChunk(const SampleBands& samples, long long pixels, InputScales scales, FeatureMap* sampleSums,
                           bool firstSums, const SumsSink* sink, Consume consume) const;
    long long applyChunks(const SampleBands& samples, int height, InputScales scales, FeatureMap& output,
                          FeatureMap* sampleSums, const SumsSink* sink) const;

    std::vector<PackedConv> layers_;          // each layer as a 1x1 convolution over samples
    std::vector<PackedGemmBf16> bf16Layers_;  // every layer in bfloat16, or none (FP32)
    // The last layer (no activation) on `count` pixels' mean hidden outputs.
    void lastLayer(const float* mean, int count, float* out) const;
    int widest_ = 0;  // most outputs of any layer
};

}  // namespace affinity
