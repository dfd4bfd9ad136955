// What the kernels filter (core/src/network/filter_signal.h, docs/MODEL.md section 6): the embedding's
// per-pixel sample sums against sums written out by hand, the radiance and demodulated signals
// made from them, and the round trip back to radiance.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "affinity/error.h"
#include "affinity/features.h"
#include "network/embedding.h"
#include "network/filter_signal.h"

namespace affinity {
namespace {

Embedding oneLayerEmbedding() {
    DenseLayer layer;
    layer.in = kFeatureCount;
    layer.out = 2;
    layer.weight.assign(std::size_t(layer.in) * layer.out, 0.1f);
    layer.bias.assign(2, 0.0f);
    return Embedding({layer});
}

// Radiance and albedo over several magnitudes, with a few non-finite or negative values.
std::vector<float> samplesWithBadValues(int pixels, int spp, std::mt19937& rng) {
    std::vector<float> samples(std::size_t(pixels) * spp * kFeatureCount, 0.5f);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    const float bad[] = {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                         -std::numeric_limits<float>::infinity(), -0.25f};
    for (std::size_t s = 0; s < std::size_t(pixels) * spp; ++s) {
        float* f = samples.data() + s * kFeatureCount;
        for (int c = 0; c < 6; ++c) f[c] = unit(rng) < 0.05f ? bad[s % 4] : 10.0f * unit(rng) * unit(rng);
        for (int c = 0; c < 3; ++c) f[channel::kAlbedo + c] = unit(rng) < 0.05f ? bad[(s + 1) % 4] : unit(rng);
        f[channel::kEmissive] = unit(rng) < 0.3f ? 1.0f : 0.0f;
        f[channel::kSpecularBounce] = unit(rng) < 0.3f ? 1.0f : 0.0f;
    }
    return samples;
}

float clean(float v) { return std::isfinite(v) && v > 0.0f ? v : 0.0f; }

TEST(SampleSums, AreTheSanitisedSumsOfTheLightOfNonEmissiveAndEmissiveSamplesAndOfAlbedo) {
    std::mt19937 rng(1);
    const int height = 5, width = 7, spp = 3, pixels = height * width;
    const std::vector<float> samples = samplesWithBadValues(pixels, spp, rng);
    FeatureMap embedding, sums;
    oneLayerEmbedding().apply(samples.data(), height, width, spp, 1.0f, embedding, &sums);
    ASSERT_EQ(sums.channels(), Embedding::kSampleSumChannels);
    int emissiveSamples = 0;
    for (int p = 0; p < pixels; ++p) {
        float expected[15] = {};
        for (int s = 0; s < spp; ++s) {
            const float* f = samples.data() + (std::size_t(p) * spp + s) * kFeatureCount;
            const bool emissive = f[channel::kEmissive] > 0.5f && f[channel::kSpecularBounce] <= 0.5f;
            emissiveSamples += emissive;
            for (int c = 0; c < 6; ++c) expected[(emissive ? 9 : 0) + c] += clean(f[c]);
            for (int c = 0; c < 3; ++c) expected[6 + c] += clean(f[channel::kAlbedo + c]);
        }
        for (int c = 0; c < 15; ++c) EXPECT_EQ(sums.data()[p * 15 + c], expected[c]) << "pixel " << p << " sum " << c;
    }
    EXPECT_GT(emissiveSamples, 10);
    EXPECT_LT(emissiveSamples, pixels * spp - 10);
}

TEST(SampleSums, BatchesAddUpToTheWholeFrameBitForBit) {
    std::mt19937 rng(2);
    const int height = 9, width = 11, pixels = height * width;
    const std::vector<float> first = samplesWithBadValues(pixels, 1, rng), rest = samplesWithBadValues(pixels, 2, rng);
    std::vector<float> whole;
    for (int p = 0; p < pixels; ++p) {
        whole.insert(whole.end(), first.begin() + p * kFeatureCount, first.begin() + (p + 1) * kFeatureCount);
        whole.insert(whole.end(), rest.begin() + p * 2 * kFeatureCount, rest.begin() + (p + 1) * 2 * kFeatureCount);
    }
    const Embedding embedding = oneLayerEmbedding();
    FeatureMap output, wholeSums, hidden, batchSums;
    embedding.apply(whole.data(), height, width, 3, 1.0f, output, &wholeSums);
    embedding.accumulate(first.data(), height, width, 1, 1.0f, hidden, true, &batchSums);
    embedding.accumulate(rest.data(), height, width, 2, 1.0f, hidden, false, &batchSums);
    for (std::size_t i = 0; i < wholeSums.size(); ++i) ASSERT_EQ(wholeSums.data()[i], batchSums.data()[i]) << i;
}

// One row of pixels from their 15 sums (Embedding::kSampleSumChannels order).
FeatureMap sumsOf(const std::vector<std::vector<float>>& pixels) {
    FeatureMap sums(1, int(pixels.size()), Embedding::kSampleSumChannels);
    for (std::size_t p = 0; p < pixels.size(); ++p)
        for (int c = 0; c < Embedding::kSampleSumChannels; ++c) sums.pixel(0, int(p))[c] = pixels[p][std::size_t(c)];
    return sums;
}

TEST(FilterSignal, RadianceIsTheMeanOfAllTheLight) {
    // Non-emissive diffuse 2 4 6, specular 1 1 2; emissive diffuse 1 0 0, specular 0 2 0.
    const FeatureMap sums = sumsOf({{2, 4, 6, 1, 1, 2, 1, 1, 1, 1, 0, 0, 0, 2, 0}});
    FeatureMap signal;
    makeAccumulatedSignal(sums, 2, SignalLayout{}, signal);
    ASSERT_EQ(signal.channels(), 3);
    EXPECT_FLOAT_EQ(signal.data()[0], 2.0f);
    EXPECT_FLOAT_EQ(signal.data()[1], 3.5f);
    EXPECT_FLOAT_EQ(signal.data()[2], 4.0f);
}

TEST(FilterSignal, EmissionBypassKeepsTheEmissiveSamplesLightApart) {
    const FeatureMap sums = sumsOf({{2, 4, 6, 1, 1, 2, 1, 1, 1, 1, 0, 0, 0, 2, 0}});
    FeatureMap signal;
    makeAccumulatedSignal(sums, 2, SignalLayout{false, true}, signal);
    ASSERT_EQ(signal.channels(), 6);
    const float* p = signal.data();
    EXPECT_FLOAT_EQ(p[0], 1.5f);  // (2 + 1) / 2, filtered
    EXPECT_FLOAT_EQ(p[2], 4.0f);
    EXPECT_FLOAT_EQ(p[3], 0.5f);  // (1 + 0) / 2, emitted
    EXPECT_FLOAT_EQ(p[4], 1.0f);
    EXPECT_FLOAT_EQ(p[5], 0.0f);
}

TEST(FilterSignal, DemodulationDividesTheDiffuseMeanByTheAlbedoMeanAboveTheFloor) {
    // Pixel 0: albedo 0.5 / 0.25 / 0.2 over 2 samples; pixel 1: black albedo (floor 0.1).
    const FeatureMap sums = sumsOf({{1.0f, 0.5f, 0.4f, 0.4f, 0.6f, 0.8f, 1.0f, 0.5f, 0.4f, 0, 0, 0, 0, 0, 0},
                                    {0.0f, 0.02f, 0.0f, 3.0f, 3.0f, 3.0f, 0.0f, 0.0f, 0.0f, 0, 0, 0, 2, 2, 2}});
    FeatureMap signal;
    makeAccumulatedSignal(sums, 2, SignalLayout{true, true}, signal);
    ASSERT_EQ(signal.channels(), 12);
    const float* p0 = signal.pixel(0, 0);
    EXPECT_FLOAT_EQ(p0[0], 0.5f / 0.5f);
    EXPECT_FLOAT_EQ(p0[1], 0.25f / 0.25f);
    EXPECT_FLOAT_EQ(p0[2], 0.2f / 0.2f);
    EXPECT_FLOAT_EQ(p0[3], 0.2f);
    EXPECT_FLOAT_EQ(p0[5], 0.4f);
    EXPECT_FLOAT_EQ(p0[7], 0.25f);  // the albedo, accumulated beside the light
    const float* p1 = signal.pixel(0, 1);
    EXPECT_FLOAT_EQ(p1[1], 0.01f / kDemodulationFloor);
    EXPECT_FLOAT_EQ(p1[4], 1.5f);
    EXPECT_FLOAT_EQ(p1[6], 0.0f);
    EXPECT_FLOAT_EQ(p1[9], 1.0f);  // emitted
}

TEST(FilterSignal, UnfilteredSignalGivesTheNoisyRadianceBack) {
    std::mt19937 rng(3);
    const int height = 6, width = 13, spp = 4;
    const std::vector<float> samples = samplesWithBadValues(height * width, spp, rng);
    FeatureMap embedding, sums;
    oneLayerEmbedding().apply(samples.data(), height, width, spp, 1.0f, embedding, &sums);
    for (int variant = 0; variant < 4; ++variant) {
        const SignalLayout layout{(variant & 1) != 0, (variant & 2) != 0};
        FeatureMap signal, filtered;
        makeAccumulatedSignal(sums, spp, layout, signal);
        // The kernels filter the first filteredChannels() of each pixel (here: not at all).
        filtered.resize(height, width, layout.filteredChannels());
        for (int p = 0; p < height * width; ++p)
            std::copy(signal.data() + std::size_t(p) * layout.channels(),
                      signal.data() + std::size_t(p) * layout.channels() + layout.filteredChannels(),
                      filtered.data() + std::size_t(p) * layout.filteredChannels());
        std::vector<float> radiance(std::size_t(height) * width * 3);
        radianceFromSignal(filtered, signal, layout, radiance.data());
        for (int p = 0; p < height * width; ++p)
            for (int c = 0; c < 3; ++c) {
                const float* sum = sums.data() + p * Embedding::kSampleSumChannels;
                const float noisy = (sum[c] + sum[3 + c] + sum[9 + c] + sum[12 + c]) / float(spp);
                EXPECT_NEAR(radiance[std::size_t(p) * 3 + c], noisy, 1e-5f * (1.0f + noisy))
                    << "pixel " << p << " variant " << variant;
            }
    }
}

TEST(FilterSignal, RejectsWrongChannelCounts) {
    FeatureMap signal, filtered;
    EXPECT_THROW(makeAccumulatedSignal(FeatureMap(2, 2, 9), 1, SignalLayout{}, signal), Error);
    EXPECT_THROW(makeAccumulatedSignal(FeatureMap(2, 2, 15), 0, SignalLayout{}, signal), Error);
    std::vector<float> out(12);
    EXPECT_THROW(radianceFromSignal(FeatureMap(2, 2, 6), FeatureMap(2, 3, 9), SignalLayout{true, false}, out.data()),
                 Error);
    EXPECT_THROW(radianceFromSignal(FeatureMap(2, 2, 6), FeatureMap(2, 2, 6), SignalLayout{true, false}, out.data()),
                 Error);
}

}  // namespace
}  // namespace affinity
