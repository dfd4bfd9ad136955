// What the kernels filter (core/src/filter_signal.h, docs/MODEL.md section 6): the embedding's
// per-pixel sample sums against sums written out by hand, the radiance and demodulated signals
// made from them, and the round trip back to radiance.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "affinity/error.h"
#include "affinity/features.h"
#include "embedding.h"
#include "filter_signal.h"

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
    }
    return samples;
}

float clean(float v) { return std::isfinite(v) && v > 0.0f ? v : 0.0f; }

TEST(SampleSums, AreTheSanitisedSumsOfDiffuseSpecularAndAlbedo) {
    std::mt19937 rng(1);
    const int height = 5, width = 7, spp = 3, pixels = height * width;
    const std::vector<float> samples = samplesWithBadValues(pixels, spp, rng);
    FeatureMap embedding, sums;
    oneLayerEmbedding().apply(samples.data(), height, width, spp, 1.0f, embedding, &sums);
    ASSERT_EQ(sums.channels(), 9);
    for (int p = 0; p < pixels; ++p) {
        float expected[9] = {};
        for (int s = 0; s < spp; ++s) {
            const float* f = samples.data() + (std::size_t(p) * spp + s) * kFeatureCount;
            for (int c = 0; c < 6; ++c) expected[c] += clean(f[c]);
            for (int c = 0; c < 3; ++c) expected[6 + c] += clean(f[channel::kAlbedo + c]);
        }
        for (int c = 0; c < 9; ++c) EXPECT_EQ(sums.data()[p * 9 + c], expected[c]) << "pixel " << p << " sum " << c;
    }
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

FeatureMap sumsOf(const std::vector<std::vector<float>>& pixels) {
    FeatureMap sums(1, int(pixels.size()), 9);
    for (std::size_t p = 0; p < pixels.size(); ++p)
        for (int c = 0; c < 9; ++c) sums.pixel(0, int(p))[c] = pixels[p][std::size_t(c)];
    return sums;
}

TEST(FilterSignal, RadianceIsTheMeanOfDiffusePlusSpecular) {
    const FeatureMap sums = sumsOf({{2, 4, 6, 1, 1, 2, 1, 1, 1}});
    FeatureMap signal;
    makeAccumulatedSignal(sums, 2, false, signal);
    ASSERT_EQ(signal.channels(), 3);
    EXPECT_FLOAT_EQ(signal.data()[0], 1.5f);
    EXPECT_FLOAT_EQ(signal.data()[1], 2.5f);
    EXPECT_FLOAT_EQ(signal.data()[2], 4.0f);
}

TEST(FilterSignal, DemodulationDividesTheDiffuseMeanByTheAlbedoMeanAboveTheFloor) {
    // Pixel 0: albedo 0.5 / 0.25 / 0.1 over 2 samples; pixel 1: black albedo (floor 0.01).
    const FeatureMap sums = sumsOf({{1.0f, 0.5f, 0.2f, 0.4f, 0.6f, 0.8f, 1.0f, 0.5f, 0.2f},
                                    {0.0f, 0.002f, 0.0f, 3.0f, 3.0f, 3.0f, 0.0f, 0.0f, 0.0f}});
    FeatureMap signal;
    makeAccumulatedSignal(sums, 2, true, signal);
    ASSERT_EQ(signal.channels(), 9);
    const float* p0 = signal.pixel(0, 0);
    EXPECT_FLOAT_EQ(p0[0], 0.5f / 0.5f);
    EXPECT_FLOAT_EQ(p0[1], 0.25f / 0.25f);
    EXPECT_FLOAT_EQ(p0[2], 0.1f / 0.1f);
    EXPECT_FLOAT_EQ(p0[3], 0.2f);
    EXPECT_FLOAT_EQ(p0[5], 0.4f);
    EXPECT_FLOAT_EQ(p0[7], 0.25f);  // the albedo, accumulated beside the light
    const float* p1 = signal.pixel(0, 1);
    EXPECT_FLOAT_EQ(p1[1], 0.001f / kDemodulationFloor);
    EXPECT_FLOAT_EQ(p1[4], 1.5f);
    EXPECT_FLOAT_EQ(p1[6], 0.0f);
}

TEST(FilterSignal, UnfilteredSignalGivesTheNoisyRadianceBack) {
    std::mt19937 rng(3);
    const int height = 6, width = 13, spp = 4;
    const std::vector<float> samples = samplesWithBadValues(height * width, spp, rng);
    FeatureMap embedding, sums;
    oneLayerEmbedding().apply(samples.data(), height, width, spp, 1.0f, embedding, &sums);
    for (const bool demodulate : {false, true}) {
        FeatureMap signal, filtered, albedo;
        makeAccumulatedSignal(sums, spp, demodulate, signal);
        splitAccumulatedSignal(signal, filtered, albedo);
        ASSERT_EQ(filtered.channels(), demodulate ? 6 : 3);
        std::vector<float> radiance(std::size_t(height) * width * 3);
        radianceFromSignal(filtered, albedo, radiance.data());
        for (int p = 0; p < height * width; ++p)
            for (int c = 0; c < 3; ++c) {
                const float* sum = sums.data() + p * 9;
                const float noisy = (sum[c] + sum[3 + c]) / float(spp);
                EXPECT_NEAR(radiance[std::size_t(p) * 3 + c], noisy, 1e-5f * (1.0f + noisy))
                    << "pixel " << p << " demodulated " << demodulate;
            }
    }
}

TEST(FilterSignal, RejectsWrongChannelCounts) {
    FeatureMap signal, filtered, albedo;
    EXPECT_THROW(makeAccumulatedSignal(FeatureMap(2, 2, 3), 1, false, signal), Error);
    EXPECT_THROW(makeAccumulatedSignal(FeatureMap(2, 2, 9), 0, false, signal), Error);
    EXPECT_THROW(splitAccumulatedSignal(FeatureMap(2, 2, 6), filtered, albedo), Error);
    std::vector<float> out(12);
    EXPECT_THROW(radianceFromSignal(FeatureMap(2, 2, 6), FeatureMap(2, 3, 3), out.data()), Error);
}

}  // namespace
}  // namespace affinity
