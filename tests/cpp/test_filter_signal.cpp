// What the kernels filter (core/src/network/filter_signal.h, docs/MODEL.md section 6): the embedding's
// per-pixel sample sums against sums written out by hand, and the radiance signal made from them.
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

// Radiance over several magnitudes, with a few non-finite or negative values, and flags (only
// the emissive one is counted, and a NaN there counts as no emitter).
std::vector<float> samplesWithBadValues(int pixels, int spp, std::mt19937& rng) {
    std::vector<float> samples(std::size_t(pixels) * spp * kFeatureCount, 0.5f);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    const float bad[] = {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                         -std::numeric_limits<float>::infinity(), -0.25f};
    for (std::size_t s = 0; s < std::size_t(pixels) * spp; ++s) {
        float* f = samples.data() + s * kFeatureCount;
        for (int c = 0; c < 6; ++c) f[c] = unit(rng) < 0.05f ? bad[s % 4] : 10.0f * unit(rng) * unit(rng);
        for (int c = 0; c < 3; ++c) f[channel::kAlbedo + c] = unit(rng) < 0.05f ? bad[(s + 1) % 4] : unit(rng);
        f[channel::kEmissive] = s % 17 == 3 ? std::numeric_limits<float>::quiet_NaN() : unit(rng) < 0.3f ? 1.0f : 0.0f;
        f[channel::kSpecularBounce] = unit(rng) < 0.3f ? 1.0f : 0.0f;
    }
    return samples;
}

float clean(float v) { return std::isfinite(v) && v > 0.0f ? v : 0.0f; }

TEST(SampleSums, AreTheSanitisedSumsOfTheLightTheSquaresAndTheEmittersOfAllSamples) {
    std::mt19937 rng(1);
    const int height = 5, width = 7, spp = 3, pixels = height * width;
    const std::vector<float> samples = samplesWithBadValues(pixels, spp, rng);
    FeatureMap embedding, sums;
    oneLayerEmbedding().apply(samples.data(), height, width, spp, 1.0f, embedding, &sums);
    ASSERT_EQ(sums.channels(), Embedding::kSampleSumChannels);
    ASSERT_EQ(Embedding::kSampleSumChannels, 8);
    float emitters = 0.0f;
    for (int p = 0; p < pixels; ++p) {
        float expected[8] = {};
        for (int s = 0; s < spp; ++s) {
            const float* f = samples.data() + (std::size_t(p) * spp + s) * kFeatureCount;
            for (int c = 0; c < 6; ++c) expected[c] += clean(f[c]);
            // Rec. 709 luminance of diffuse + specular, squared.
            const double y = 0.2126 * (clean(f[0]) + clean(f[3])) + 0.7152 * (clean(f[1]) + clean(f[4])) +
                             0.0722 * (clean(f[2]) + clean(f[5]));
            expected[6] += float(y * y);
            expected[7] += f[channel::kEmissive] == 1.0f ? 1.0f : 0.0f;
        }
        for (int c = 0; c < 6; ++c) EXPECT_EQ(sums.data()[p * 8 + c], expected[c]) << "pixel " << p << " sum " << c;
        EXPECT_NEAR(sums.data()[p * 8 + 6], expected[6], 1e-5 * expected[6] + 1e-30) << "pixel " << p;
        EXPECT_EQ(sums.data()[p * 8 + 7], expected[7]) << "pixel " << p;
        emitters += expected[7];
    }
    EXPECT_GT(emitters, 10.0f);  // the flags were there to count
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

TEST(FilterSignal, RadianceIsTheMeanOfAllTheLight) {
    // Diffuse 2 4 6, specular 1 1 2, summed over 2 samples.
    FeatureMap sums(1, 1, Embedding::kSampleSumChannels);
    const float values[] = {2, 4, 6, 1, 1, 2};
    std::copy(std::begin(values), std::end(values), sums.data());
    FeatureMap signal;
    makeAccumulatedSignal(sums, 2, signal);
    ASSERT_EQ(signal.channels(), kSignalChannels);
    EXPECT_FLOAT_EQ(signal.data()[0], 1.5f);
    EXPECT_FLOAT_EQ(signal.data()[1], 2.5f);
    EXPECT_FLOAT_EQ(signal.data()[2], 4.0f);
}

TEST(SampleMeans, AreTheMeanSquaredLuminanceAndTheShareOfEmitters) {
    // Three samples of luminance 1, 2 and 6 (grey light split between diffuse and specular), one
    // of which saw an emitter.
    FeatureMap sums(1, 1, Embedding::kSampleSumChannels);
    const float values[] = {5, 5, 5, 4, 4, 4, 1 + 4 + 36, 1};
    std::copy(std::begin(values), std::end(values), sums.data());
    FeatureMap meanSquares, emissiveShare;
    makeSampleMeans(sums, 3, Embedding::kSumLuminanceSquares, meanSquares);
    ASSERT_EQ(meanSquares.channels(), 1);
    EXPECT_FLOAT_EQ(meanSquares.data()[0], 41.0f / 3.0f);
    makeSampleMeans(sums, 3, Embedding::kSumEmissive, emissiveShare);
    EXPECT_FLOAT_EQ(emissiveShare.data()[0], 1.0f / 3.0f);
    // Squares that overflowed stay finite (the box sums that read them could not take an infinity).
    sums.data()[6] = std::numeric_limits<float>::infinity();
    makeSampleMeans(sums, 3, Embedding::kSumLuminanceSquares, meanSquares);
    EXPECT_EQ(meanSquares.data()[0], 1e30f);
}

TEST(FilterSignal, RejectsWrongChannelCounts) {
    FeatureMap signal;
    EXPECT_THROW(makeAccumulatedSignal(FeatureMap(2, 2, 9), 1, signal), Error);
    EXPECT_THROW(makeAccumulatedSignal(FeatureMap(2, 2, Embedding::kSampleSumChannels), 0, signal), Error);
    EXPECT_THROW(makeSampleMeans(FeatureMap(2, 2, 6), 2, Embedding::kSumLuminanceSquares, signal), Error);
    EXPECT_THROW(makeSampleMeans(FeatureMap(2, 2, Embedding::kSampleSumChannels), 2, 8, signal), Error);
}

}  // namespace
}  // namespace affinity
