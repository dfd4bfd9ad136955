#include "network/embedding.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>

#include "affinity/error.h"
#include "affinity/features.h"
#include "kernels/aligned_allocator.h"
#include "kernels/fast_exp.h"
#include "kernels/fast_log1p.h"
#include "kernels/luminance.h"

namespace affinity {
namespace {

// Samples per work item: the item's activations (two buffers of this many rows) stay in L1.
constexpr int kChunkSamples = 96;
constexpr int kRadianceChannels = 6;  // diffuse and specular, in front of the other features
static_assert(channel::kDiffuse == 0 && channel::kSpecular == 3, "radiance leads the sample");

// Eight floats from anywhere (no alignment needed).
Vec8f load8(const float* p) {
    Vec8f v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

// The input transform of MODEL.md section 1 for `count` consecutive samples into `input`
// ([count][18]): non-finite values read as 0, radiance (features 0-5) also where negative or
// above kMaxRadiance, and then as log(1 + exposure r), depth times the depth scale. The sanitised linear radiance goes to `radiance`
// ([count][6] + 2 floats of padding) for the sample sums. One pass, a sample at a time in
// 8-lane pieces (features 0-7, 8-15, then 16-17). Returns how many radiance values were
// non-finite, negative or above kMaxRadiance.
long long prepareSamples(const float* samples, int count, InputScales scales, float* input, float* radiance) {
    static_assert(kFeatureCount == 18 && channel::kDepth == 9, "the lanes below follow features.h");
    auto store = [](float* p, Vec8f v) { std::memcpy(p, &v, sizeof v); };
    auto finiteOrZero = [](float v) { return std::fabs(v) <= 3.40282347e38f ? v : 0.0f; };
    const Vec8f largest = broadcast8(3.40282347e38f), maxRadiance = broadcast8(kMaxRadiance);
    const Vec8i isRadiance = Vec8i{0, 1, 2, 3, 4, 5, 6, 7} < kRadianceChannels;
    const Vec8f depthFactor = Vec8f{1.0f, scales.depth, 1.0f, 1.0f, 1.0f, 1.0f, 1.0f, 1.0f};
    const Vec8f exposure = broadcast8(scales.exposure);
    Vec8i bad{};
    for (int s = 0; s < count; ++s) {
        const float* raw = samples + std::size_t(s) * kFeatureCount;
        // 32 samples ahead: on Intel the hardware streamer stops at each 4 KiB page and this
        // pass waited on memory (on Zen 4 a prefetch changed nothing). A prefetch never faults;
        // the address is formed as an integer because it may lie past the frame.
        __builtin_prefetch(
            reinterpret_cast<const void*>(reinterpret_cast<std::uintptr_t>(raw) + 32 * kFeatureCount * sizeof(float)));
        float* in = input + std::size_t(s) * kFeatureCount;
        const Vec8f low = load8(raw), high = load8(raw + 8);
        // False for NaN and +-Inf; radiance must also not be negative.
        const Vec8i lowOk = (low >= (isRadiance ? Vec8f{} : -largest)) & (low <= (isRadiance ? maxRadiance : largest));
        const Vec8i highOk = (high >= -largest) & (high <= largest);
        bad -= isRadiance & ~lowOk;  // a true comparison is -1
        const Vec8f lowClean = lowOk ? low : Vec8f{};
        store(radiance + std::size_t(s) * kRadianceChannels, lowClean);  // lanes 6-7: padding, overwritten next
        const Vec8f exposed = lowClean * exposure;                       // kept finite: log1p needs it
        const Vec8f finiteExposed = exposed <= largest ? exposed : largest;
        store(in, isRadiance ? log1pNonNegative8(isRadiance ? finiteExposed : Vec8f{}) : lowClean);
        store(in + 8, (highOk ? high : Vec8f{}) * depthFactor);
        in[16] = finiteOrZero(raw[16]);
        in[17] = finiteOrZero(raw[17]);
    }
    long long total = 0;
    for (int l = 0; l < 8; ++l) total += bad[l];
    return total;
}

// Adds each of `pixels` pixels' Embedding::kSampleSumChannels sums (diffuse and specular RGB of
// the sanitised `radiance`, the squared luminance, and the samples flagged emissive in the raw
// `features`) over its spp samples in order to `sums`, starting from 0 when `first`: one 8-lane
// add per sample (6 lanes used). `radiance` must have 2 readable floats past its last sample.
void addSampleSums(const float* radiance, const float* features, int pixels, int spp, bool first, float* sums) {
    constexpr int kSums = Embedding::kSampleSumChannels;
    static_assert(Embedding::kSumDiffuse == 0 && Embedding::kSumSpecular == 3 &&
                      Embedding::kSumLuminanceSquares == kRadianceChannels &&
                      Embedding::kSumEmissive == kRadianceChannels + 1 && kSums == kRadianceChannels + 2,
                  "the sums are laid out as a sample's radiance, then the squares and the emitters");
    for (int p = 0; p < pixels; ++p) {
        float* o = sums + std::size_t(p) * kSums;
        Vec8f sum{};
        float squares = first ? 0.0f : o[Embedding::kSumLuminanceSquares];
        float emitters = first ? 0.0f : o[Embedding::kSumEmissive];
        if (!first)
            for (int c = 0; c < kRadianceChannels; ++c) sum[c] = o[c];
        for (int s = 0; s < spp; ++s) {
            const float* sample = radiance + (std::size_t(p) * spp + std::size_t(s)) * kRadianceChannels;
            sum += load8(sample);
            const float light[3] = {sample[0] + sample[3], sample[1] + sample[4], sample[2] + sample[5]};
            const float y = luminance(light);
            squares += y * y;
            // NaN and other garbage count as no emitter.
            if (features[(std::size_t(p) * spp + std::size_t(s)) * kFeatureCount + channel::kEmissive] > 0.5f)
                emitters += 1.0f;
        }
        for (int c = 0; c < kRadianceChannels; ++c) o[c] = sum[c];
        o[Embedding::kSumLuminanceSquares] = squares;
        o[Embedding::kSumEmissive] = emitters;
    }
}

// sum[c] (= 0 when `first`) += each of the spp samples' hidden[s][c], in sample order. One
// vectorised pass over the channels per sample: looping over samples inside the channel loop
// left the compiler with scalar adds.
void addSamplesOfPixel(const float* __restrict hidden, int spp, int channels, bool first, float* __restrict sum) {
    int s = 0;
    if (first) {
#pragma omp simd
        for (int c = 0; c < channels; ++c) sum[c] = hidden[c];
        s = 1;
    }
    for (; s < spp; ++s) {
        const float* __restrict h = hidden + std::size_t(s) * channels;
#pragma omp simd
        for (int c = 0; c < channels; ++c) sum[c] += h[c];
    }
}

void scaleValues(float* values, int count, float factor) {
#pragma omp simd
    for (int i = 0; i < count; ++i) values[i] *= factor;
}

}  // namespace

Embedding::Embedding(std::vector<DenseLayer> layers, Precision precision) {
    if (layers.empty()) throw Error("Embedding: no layers");
    int expected = kFeatureCount;
    for (std::size_t i = 0; i < layers.size(); ++i) {
        const DenseLayer& layer = layers[i];
        const std::string name = "Embedding layer " + std::to_string(i);
        if (layer.in != expected)
            throw Error(name + " takes " + std::to_string(layer.in) + " inputs, expected " + std::to_string(expected));
        if (layer.out <= 0) throw Error(name + " has " + std::to_string(layer.out) + " outputs");
        if (layer.weight.size() != std::size_t(layer.in) * std::size_t(layer.out))
            throw Error(name + ": weight has " + std::to_string(layer.weight.size()) + " values, expected " +
                        std::to_string(std::size_t(layer.in) * std::size_t(layer.out)));
        if (layer.bias.size() != std::size_t(layer.out))
            throw Error(name + ": bias has " + std::to_string(layer.bias.size()) + " values, expected " +
                        std::to_string(layer.out));
        layers_.emplace_back(layer.weight.data(), layer.bias.data(), layer.out, layer.in, 1);
        widest_ = std::max(widest_, layer.out);
        expected = layer.out;
    }
    const bool pairs = std::all_of(layers.begin(), layers.end(), [](const DenseLayer& l) { return l.in % 2 == 0; });
    if (precision == Precision::BFloat16 && pairs)
        for (const DenseLayer& layer : layers)
            bf16Layers_.emplace_back(layer.weight.data(), layer.out, layer.in, layer.bias.data());
}

void Embedding::lastLayer(const float* mean, int count, float* out) const {
    const int channels = hiddenChannels();
    if (bf16Layers_.empty()) {
        const ConvSource meanSource{mean, channels};
        convolveRow(layers_.back(), &meanSource, 1, 1, count, 0, 0, count, Activation::None, out);
        return;
    }
    gemmBf16(bf16Layers_.back(), mean, count, out, std::size_t(outChannels()));
}

int Embedding::outChannels() const { return layers_.back().outChannels(); }

int Embedding::hiddenChannels() const {
    return layers_.size() == 1 ? kFeatureCount : layers_[layers_.size() - 2].outChannels();
}

template <class Consume>
long long Embedding::forEachChunk(const SampleBands& samples, long long pixels, InputScales scales,
                                  FeatureMap* sampleSums, bool firstSums, const SumsSink* sink, Consume consume) const {
    const int spp = samples.spp;
    const int chunkPixels = std::max(1, kChunkSamples / spp);
    const int chunkSamples = chunkPixels * spp;
    const long long chunks = (pixels + chunkPixels - 1) / chunkPixels;
    const std::size_t layerCount = layers_.size();
    long long bad = 0;

#pragma omp parallel reduction(+ : bad) if (pixels * spp >= 4096)
    {
        // + 2: addSampleSums reads 8 floats at each sample's 6.
        AlignedVector<float> radiance(std::size_t(chunkSamples) * kRadianceChannels + 2);
        AlignedVector<float> input(std::size_t(chunkSamples) * kFeatureCount);
        AlignedVector<float> ping(std::size_t(chunkSamples) * widest_);
        AlignedVector<float> pong(std::size_t(chunkSamples) * widest_);
        AlignedVector<float> scratch(std::size_t(chunkPixels) * std::max(hiddenChannels(), kFeatureCount));
        std::vector<float> gather(samples.bands.size() > 1 ? std::size_t(chunkSamples) * kFeatureCount : 0);
        std::vector<float> chunkSums(sink && !sampleSums ? std::size_t(chunkPixels) * kSampleSumChannels : 0);

#pragma omp for schedule(dynamic, 16)
        for (long long chunk = 0; chunk < chunks; ++chunk) {
            const long long p0 = chunk * chunkPixels;
            const int count = int(std::min<long long>(chunkPixels, pixels - p0));
            const int n = count * spp;
            const float* chunkInput = samples.pixels(p0, count, gather.data());
            bad += prepareSamples(chunkInput, n, scales, input.data(), radiance.data());
            if (sampleSums) {
                addSampleSums(radiance.data(), chunkInput, count, spp, firstSums,
                              sampleSums->data() + std::size_t(p0) * kSampleSumChannels);
            } else if (sink) {
                addSampleSums(radiance.data(), chunkInput, count, spp, true, chunkSums.data());
                (*sink)(p0, count, chunkSums.data());
            }

            // Hidden layers per sample; `source` is what feeds the next layer.
            ConvSource source{input.data(), kFeatureCount};
            float* next = ping.data();
            for (std::size_t l = 0; l + 1 < layerCount; ++l) {
                if (bf16Layers_.empty()) {
                    convolveRow(layers_[l], &source, 1, 1, n, 0, 0, n, Activation::LeakyRelu, next);
                } else {
                    gemmBf16(bf16Layers_[l], source.data, n, next, std::size_t(layers_[l].outChannels()), true);
                }
                source = {next, layers_[l].outChannels()};
                next = next == ping.data() ? pong.data() : ping.data();
            }
            consume(p0, count, source.data, scratch.data());
        }
    }
    return bad;
}

const float* SampleBands::pixels(long long first, int count, float* gather) const {
    const long long bandPixels = (long long)bandRows * width;
    const std::size_t values = pixelValues();
    const long long band = first / bandPixels, last = (first + count - 1) / bandPixels;
    if (band == last) return bands[std::size_t(band)] + std::size_t(first - band * bandPixels) * values;
    for (int p = 0; p < count; ++p) {
        const long long pixel = first + p, b = pixel / bandPixels;
        const float* from = bands[std::size_t(b)] + std::size_t(pixel - b * bandPixels) * values;
        std::copy(from, from + values, gather + std::size_t(p) * values);
    }
    return gather;
}

long long Embedding::apply(const SampleBands& samples, int height, InputScales scales, FeatureMap& output,
                           FeatureMap* sampleSums) const {
    return applyChunks(samples, height, scales, output, sampleSums, nullptr);
}

long long Embedding::apply(const SampleBands& samples, int height, InputScales scales, FeatureMap& output,
                           const SumsSink& sink) const {
    return applyChunks(samples, height, scales, output, nullptr, &sink);
}

long long Embedding::applyChunks(const SampleBands& samples, int height, InputScales scales, FeatureMap& output,
                                 FeatureMap* sampleSums, const SumsSink* sink) const {
    const int width = samples.width, spp = samples.spp;
    if (height < 0 || width < 0 || spp <= 0)
        throw Error("Embedding: bad frame size " + std::to_string(height) + "x" + std::to_string(width) + " with " +
                    std::to_string(spp) + " samples per pixel");
    output.resize(height, width, outChannels());
    if (sampleSums) sampleSums->resize(height, width, kSampleSumChannels);
    const long long pixels = (long long)height * width;
    if (pixels == 0) return 0;

    // The last layer has no activation, so the mean over samples commutes with it: average
    // the previous layer's outputs and apply the last layer once per pixel instead of once
    // per sample (the same function up to float rounding, and S times fewer operations there).
    const int channels = hiddenChannels();
    const float inverseSpp = 1.0f / float(spp);
    return forEachChunk(samples, pixels, scales, sampleSums, true, sink,
                        [&](long long p0, int count, const float* hidden, float* mean) {
                            // Mean over each pixel's samples, added in sample order.
                            for (int p = 0; p < count; ++p)
                                addSamplesOfPixel(hidden + std::size_t(p) * spp * channels, spp, channels, true,
                                                  mean + std::size_t(p) * channels);
                            scaleValues(mean, count * channels, inverseSpp);
                            lastLayer(mean, count, output.data() + std::size_t(p0) * outChannels());
                        });
}

long long Embedding::accumulate(const float* samples, int height, int width, int spp, InputScales scales,
                                FeatureMap& hiddenSum, bool first, FeatureMap* sampleSums) const {
    if (height < 0 || width < 0 || spp <= 0)
        throw Error("Embedding: bad frame size " + std::to_string(height) + "x" + std::to_string(width) + " with " +
                    std::to_string(spp) + " samples per pixel");
    const int channels = hiddenChannels();
    if (first) {
        hiddenSum.resize(height, width, channels);
        if (sampleSums) sampleSums->resize(height, width, kSampleSumChannels);
    } else if (hiddenSum.height() != height || hiddenSum.width() != width || hiddenSum.channels() != channels ||
               (sampleSums && (sampleSums->height() != height || sampleSums->width() != width ||
                               sampleSums->channels() != kSampleSumChannels))) {
        throw Error("Embedding: a batch of " + std::to_string(height) + "x" + std::to_string(width) +
                    " does not match the sums it is added to");
    }
    const long long pixels = (long long)height * width;
    if (pixels == 0) return 0;
    // The same additions in the same order as apply()'s mean, without the final scaling.
    return forEachChunk(SampleBands(samples, height, width, spp), pixels, scales, sampleSums, first, nullptr,
                        [&](long long p0, int count, const float* hidden, float*) {
                            for (int p = 0; p < count; ++p) {
                                float* m = hiddenSum.data() + (std::size_t(p0) + std::size_t(p)) * channels;
                                addSamplesOfPixel(hidden + std::size_t(p) * spp * channels, spp, channels, first, m);
                            }
                        });
}

void Embedding::finish(const FeatureMap& hiddenSum, int spp, FeatureMap& output) const {
    const int channels = hiddenChannels();
    if (hiddenSum.channels() != channels || spp <= 0)
        throw Error("Embedding: finish needs a sum of " + std::to_string(channels) + " channels over >= 1 sample");
    if (&output == &hiddenSum && outChannels() != channels)
        throw Error("Embedding: finish in place needs as many output channels as hidden ones");
    output.resize(hiddenSum.height(), hiddenSum.width(), outChannels());
    const long long pixels = (long long)hiddenSum.height() * hiddenSum.width();
    const float inverseSpp = 1.0f / float(spp);
    const int chunkPixels = kChunkSamples;
    const long long chunks = (pixels + chunkPixels - 1) / chunkPixels;
#pragma omp parallel if (pixels >= 4096)
    {
        AlignedVector<float> mean(std::size_t(chunkPixels) * channels);
#pragma omp for schedule(static)
        for (long long chunk = 0; chunk < chunks; ++chunk) {
            const long long p0 = chunk * chunkPixels;
            const int count = int(std::min<long long>(chunkPixels, pixels - p0));
            const float* sum = hiddenSum.data() + std::size_t(p0) * channels;
            const std::size_t values = std::size_t(count) * channels;
#pragma omp simd
            for (std::size_t i = 0; i < values; ++i) mean[i] = sum[i] * inverseSpp;
            lastLayer(mean.data(), count, output.data() + std::size_t(p0) * outChannels());
        }
    }
}

}  // namespace affinity
