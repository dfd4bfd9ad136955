// The embedding (docs/MODEL.md sections 1-2) against a naive double-precision reference:
// input transform, MLP, mean over samples; robustness to bad radiance; sample-order and
// thread-count independence; the vectorised log1p it relies on.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "affinity/error.h"
#include "affinity/features.h"
#include "network/embedding.h"
#include "pipeline/exposure.h"
#include "kernels/fast_log1p.h"

namespace affinity {
namespace {

std::vector<DenseLayer> randomLayers(const std::vector<int>& widths, std::mt19937& rng) {
    std::vector<DenseLayer> layers;
    for (std::size_t i = 0; i + 1 < widths.size(); ++i) {
        DenseLayer layer;
        layer.in = widths[i];
        layer.out = widths[i + 1];
        const float scale = 1.5f / std::sqrt(float(layer.in));
        std::uniform_real_distribution<float> dist(-scale, scale);
        layer.weight.resize(std::size_t(layer.in) * layer.out);
        for (float& v : layer.weight) v = dist(rng);
        layer.bias.resize(std::size_t(layer.out));
        for (float& v : layer.bias) v = dist(rng);
        layers.push_back(std::move(layer));
    }
    return layers;
}

// Plausible renderer output: radiance over many magnitudes, unit normals, depth, flags.
std::vector<float> randomSamples(long long count, std::mt19937& rng) {
    std::vector<float> samples(std::size_t(count) * kFeatureCount);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::normal_distribution<float> normal(0.0f, 1.0f);
    for (long long s = 0; s < count; ++s) {
        float* f = samples.data() + s * kFeatureCount;
        for (int k = 0; k < 6; ++k) {
            const float u = unit(rng);
            f[k] = u < 0.1f ? 0.0f : std::exp(normal(rng) * 3.0f);  // 0 and ~1e-4 .. 1e4
        }
        float n[3] = {normal(rng), normal(rng), normal(rng)};
        const float length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) + 1e-6f;
        for (int k = 0; k < 3; ++k) f[channel::kNormal + k] = n[k] / length;
        f[channel::kDepth] = unit(rng) < 0.1f ? 0.0f : 50.0f * unit(rng);
        for (int k = 0; k < 3; ++k) f[channel::kAlbedo + k] = unit(rng);
        f[channel::kRoughness] = std::max(kRoughnessFloor, unit(rng));
        for (int k = channel::kEmissive; k < kFeatureCount; ++k) f[k] = unit(rng) < 0.3f ? 1.0f : 0.0f;
    }
    return samples;
}

// The definition, term by term, in double precision.
std::vector<double> referenceEmbedding(const std::vector<DenseLayer>& layers, const float* samples, long long pixels,
                                       int spp, float depthScale, long long& badCount) {
    const int e = layers.back().out;
    std::vector<double> result(std::size_t(pixels) * e, 0.0);
    badCount = 0;
    for (long long p = 0; p < pixels; ++p)
        for (int s = 0; s < spp; ++s) {
            const float* f = samples + (std::size_t(p) * spp + s) * kFeatureCount;
            std::vector<double> h(f, f + kFeatureCount);
            for (int k = 0; k < 6; ++k) {
                if (!std::isfinite(f[k]) || f[k] < 0) {
                    ++badCount;
                    h[k] = 0.0;
                }
                h[k] = std::log1p(h[k]);
            }
            h[channel::kDepth] = double(f[channel::kDepth]) * depthScale;
            for (std::size_t l = 0; l < layers.size(); ++l) {
                const DenseLayer& layer = layers[l];
                std::vector<double> next(std::size_t(layer.out));
                for (int o = 0; o < layer.out; ++o) {
                    double sum = layer.bias[o];
                    for (int i = 0; i < layer.in; ++i)
                        sum += double(layer.weight[std::size_t(o) * layer.in + i]) * h[i];
                    if (l + 1 < layers.size() && sum < 0) sum *= 0.01;
                    next[o] = sum;
                }
                h = std::move(next);
            }
            for (int c = 0; c < e; ++c) result[std::size_t(p) * e + c] += h[c] / spp;
        }
    return result;
}

struct Case {
    std::vector<int> widths;
    int height, width, spp;
};

std::string describe(const Case& c) {
    std::string text;
    for (int w : c.widths) text += std::to_string(w) + "-";
    return text + " " + std::to_string(c.height) + "x" + std::to_string(c.width) + " spp " + std::to_string(c.spp);
}

TEST(Embedding, MatchesReference) {
    std::mt19937 rng(1);
    const Case cases[] = {
        {{18, 32, 32, 32}, 7, 13, 4}, {{18, 32, 32, 32}, 1, 1, 1},  {{18, 5}, 33, 17, 3},
        {{18, 13, 7}, 1, 7, 8},       {{18, 35, 3, 16}, 7, 13, 2},  {{18, 32, 32, 32}, 3, 5, 200},
        {{18, 16, 8}, 33, 17, 1},     {{18, 8, 8, 8, 8}, 13, 7, 5},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(describe(c));
        const std::vector<DenseLayer> layers = randomLayers(c.widths, rng);
        const Embedding embedding(layers);
        ASSERT_EQ(embedding.outChannels(), c.widths.back());
        const long long pixels = (long long)c.height * c.width;
        const std::vector<float> samples = randomSamples(pixels * c.spp, rng);
        const float depthScale = 0.04f;
        FeatureMap output;
        EXPECT_EQ(embedding.apply(samples.data(), c.height, c.width, c.spp, depthScale, output), 0);
        ASSERT_EQ(output.height(), c.height);
        ASSERT_EQ(output.width(), c.width);
        ASSERT_EQ(output.channels(), c.widths.back());
        long long badCount = -1;
        const std::vector<double> expected =
            referenceEmbedding(layers, samples.data(), pixels, c.spp, depthScale, badCount);
        EXPECT_EQ(badCount, 0);
        int bad = 0;
        for (std::size_t i = 0; i < expected.size(); ++i) {
            // Values are O(1-10); float rounding through a few layers stays near 1e-6.
            if (!(std::abs(output.data()[i] - expected[i]) <= 1e-5 * (1.0 + std::abs(expected[i])))) {
                if (bad < 3)
                    ADD_FAILURE() << "value " << i << ": got " << output.data()[i] << ", expected " << expected[i];
                ++bad;
            }
        }
        ASSERT_EQ(bad, 0);
    }
}

TEST(Embedding, SampleOrderDoesNotMatter) {
    std::mt19937 rng(2);
    const std::vector<DenseLayer> layers = randomLayers({18, 32, 32, 32}, rng);
    const Embedding embedding(layers);
    const int height = 9, width = 11, spp = 7;
    const std::vector<float> samples = randomSamples((long long)height * width * spp, rng);
    std::vector<float> permuted = samples;
    for (int p = 0; p < height * width; ++p) {
        std::vector<int> order(spp);
        for (int s = 0; s < spp; ++s) order[s] = s;
        std::shuffle(order.begin(), order.end(), rng);
        for (int s = 0; s < spp; ++s)
            std::memcpy(permuted.data() + (std::size_t(p) * spp + s) * kFeatureCount,
                        samples.data() + (std::size_t(p) * spp + order[s]) * kFeatureCount,
                        kFeatureCount * sizeof(float));
    }
    FeatureMap a, b;
    embedding.apply(samples.data(), height, width, spp, 0.05f, a);
    embedding.apply(permuted.data(), height, width, spp, 0.05f, b);
    double worst = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i)
        worst = std::max(worst, std::abs(double(a.data()[i]) - b.data()[i]) / (1.0 + std::abs(a.data()[i])));
    EXPECT_LE(worst, 2e-6);
}

TEST(Embedding, BadRadianceIsZeroAndCounted) {
    std::mt19937 rng(3);
    const std::vector<DenseLayer> layers = randomLayers({18, 32, 32, 32}, rng);
    const Embedding embedding(layers);
    const int height = 5, width = 7, spp = 4;
    std::vector<float> samples = randomSamples((long long)height * width * spp, rng);
    std::vector<float> cleaned = samples;
    const float poison[] = {std::numeric_limits<float>::quiet_NaN(),
                            std::numeric_limits<float>::infinity(),
                            -std::numeric_limits<float>::infinity(),
                            -1.0f,
                            -1e-30f,
                            -std::numeric_limits<float>::signaling_NaN()};
    long long expectedCount = 0;
    std::uniform_int_distribution<int> pick(0, 5);
    for (int s = 0; s < height * width * spp; s += 3) {
        const int k = pick(rng);
        samples[std::size_t(s) * kFeatureCount + k] = poison[(s / 3) % 6];
        cleaned[std::size_t(s) * kFeatureCount + k] = 0.0f;
        ++expectedCount;
    }
    // -0 is not negative: neither changed nor counted.
    samples[kFeatureCount + 2] = -0.0f;
    cleaned[kFeatureCount + 2] = 0.0f;

    FeatureMap dirty, clean;
    EXPECT_EQ(embedding.apply(samples.data(), height, width, spp, 0.05f, dirty), expectedCount);
    EXPECT_EQ(embedding.apply(cleaned.data(), height, width, spp, 0.05f, clean), 0);
    for (std::size_t i = 0; i < dirty.size(); ++i) ASSERT_TRUE(std::isfinite(dirty.data()[i])) << i;
    EXPECT_EQ(std::memcmp(dirty.data(), clean.data(), dirty.size() * sizeof(float)), 0);

    long long referenceCount = 0;
    const std::vector<double> expected =
        referenceEmbedding(layers, samples.data(), (long long)height * width, spp, 0.05f, referenceCount);
    EXPECT_EQ(referenceCount, expectedCount);
    for (std::size_t i = 0; i < expected.size(); ++i)
        ASSERT_NEAR(dirty.data()[i], expected[i], 1e-5 * (1.0 + std::abs(expected[i]))) << i;
}

TEST(Embedding, ThreadCountDoesNotChangeResults) {
    std::mt19937 rng(4);
    const Embedding embedding(randomLayers({18, 32, 32, 32}, rng));
    const int height = 37, width = 91, spp = 3;
    std::vector<float> samples = randomSamples((long long)height * width * spp, rng);
    samples[5] = std::numeric_limits<float>::quiet_NaN();
    const int saved = omp_get_max_threads();
    FeatureMap one, two;
    omp_set_num_threads(1);
    const long long badOne = embedding.apply(samples.data(), height, width, spp, 0.1f, one);
    omp_set_num_threads(2);
    const long long badTwo = embedding.apply(samples.data(), height, width, spp, 0.1f, two);
    omp_set_num_threads(saved);
    EXPECT_EQ(badOne, 1);
    EXPECT_EQ(badTwo, 1);
    EXPECT_EQ(std::memcmp(one.data(), two.data(), one.size() * sizeof(float)), 0);
}

// Streaming (pipeline/frame_input.cpp) finishes in place when the last layer keeps the width: every chunk
// must be read before it is overwritten, whatever the threads do.
TEST(Embedding, FinishInPlaceGivesApplysResultBitForBit) {
    std::mt19937 rng(6);
    const Embedding embedding(randomLayers({18, 32, 32, 32}, rng));
    const int height = 41, width = 131, spp = 3;  // several chunks per thread
    const std::vector<float> samples = randomSamples((long long)height * width * spp, rng);
    FeatureMap expected;
    embedding.apply(samples.data(), height, width, spp, 0.2f, expected);
    // Batches of one and two samples per pixel, taken out of the frame's [pixel][sample] layout.
    std::vector<float> first, second;
    for (long long p = 0; p < (long long)height * width; ++p) {
        const float* pixel = samples.data() + p * spp * kFeatureCount;
        first.insert(first.end(), pixel, pixel + kFeatureCount);
        second.insert(second.end(), pixel + kFeatureCount, pixel + spp * kFeatureCount);
    }
    FeatureMap sums;
    embedding.accumulate(first.data(), height, width, 1, 0.2f, sums, true);
    embedding.accumulate(second.data(), height, width, spp - 1, 0.2f, sums, false);
    embedding.finish(sums, spp, sums);
    ASSERT_EQ(sums.channels(), expected.channels());
    EXPECT_EQ(std::memcmp(sums.data(), expected.data(), expected.size() * sizeof(float)), 0);

    const Embedding narrowing(randomLayers({18, 32, 8}, rng));
    FeatureMap hidden;
    narrowing.accumulate(first.data(), height, width, 1, 0.2f, hidden, true);
    EXPECT_THROW(narrowing.finish(hidden, 1, hidden), Error);
}

TEST(Embedding, DepthIsScaled) {
    // One linear layer reading only depth: e = depth * depthScale.
    DenseLayer layer;
    layer.in = kFeatureCount;
    layer.out = 1;
    layer.weight.assign(kFeatureCount, 0.0f);
    layer.weight[channel::kDepth] = 1.0f;
    layer.bias = {0.0f};
    const Embedding embedding({layer});
    std::vector<float> samples(2 * kFeatureCount, 0.0f);
    samples[channel::kDepth] = 10.0f;
    samples[kFeatureCount + channel::kDepth] = 30.0f;
    FeatureMap output;
    embedding.apply(samples.data(), 1, 1, 2, 0.25f, output);
    EXPECT_FLOAT_EQ(output.data()[0], 5.0f);
}

TEST(Embedding, TheExposureScalesTheRadianceBeforeTheLog) {
    // Radiance times e at exposure 1 is radiance at exposure e, bit for bit (the same product).
    std::mt19937 rng(9);
    const Embedding embedding(randomLayers({18, 16, 8}, rng));
    const int height = 5, width = 7, spp = 2;
    std::uniform_real_distribution<float> u(0.0f, 3.0f);
    std::vector<float> samples(std::size_t(height) * width * spp * kFeatureCount), scaled;
    for (float& v : samples) v = u(rng);
    scaled = samples;
    const float exposure = 0.37f;
    for (std::size_t i = 0; i < scaled.size(); i += kFeatureCount)
        for (int c = 0; c < 6; ++c) scaled[i + std::size_t(channel::kDiffuse + c)] *= exposure;
    FeatureMap a, b;
    embedding.apply(samples.data(), height, width, spp, InputScales(0.2f, exposure), a);
    embedding.apply(scaled.data(), height, width, spp, 0.2f, b);
    EXPECT_TRUE(std::equal(a.data(), a.data() + a.size(), b.data()));
    // A huge exposure saturates at log(1 + FLT_MAX) instead of overflowing.
    embedding.apply(samples.data(), height, width, spp, InputScales(0.2f, 1e38f), a);
    EXPECT_TRUE(std::all_of(a.data(), a.data() + a.size(), [](float v) { return std::isfinite(v); }));
}

// A frame (height x width x 1 sample) whose pixels have grey diffuse radiance value(x, y).
template <class Value>
std::vector<float> greyFrame(int height, int width, Value value) {
    std::vector<float> samples(std::size_t(height) * width * kFeatureCount, 0.0f);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x)
            for (int c = 0; c < 3; ++c)
                samples[(std::size_t(y) * width + x) * kFeatureCount + std::size_t(channel::kDiffuse + c)] =
                    value(x, y);
    return samples;
}

TEST(Exposure, KeyIsTheGeometricMeanOfTheSquaresByHand) {
    // Two 16x16 squares, grey 0.5 and 2 (luminance weights sum to 1): key sqrt(0.5 * 2) = 1, above
    // the trained range's 0.64, so the radiance is scaled by 0.64. Only every 4th row is read: the other
    // rows hold 1000, which must not count.
    const auto samples = greyFrame(16, 32, [](int x, int y) { return y % 4 ? 1000.0f : (x < 16 ? 0.5f : 2.0f); });
    EXPECT_NEAR(exposureOf(SampleBands(samples.data(), 16, 32, 1), 16), 0.64, 1e-6);
    // Keys inside [0.0013, 0.64] are left alone; below, brought up to 0.0013.
    const auto inside = greyFrame(16, 32, [](int x, int) { return x < 16 ? 0.01f : 0.04f; });  // key 0.02
    EXPECT_EQ(exposureOf(SampleBands(inside.data(), 16, 32, 1), 16), 1.0f);
    const auto dim = greyFrame(16, 32, [](int x, int) { return x < 16 ? 0.0001f : 0.0004f; });  // key 0.0002
    EXPECT_NEAR(exposureOf(SampleBands(dim.data(), 16, 32, 1), 16), 6.5, 1e-5);
    // Partial squares average the pixels they have: a 20x18 frame, 4 squares, each uniform.
    const auto partial =
        greyFrame(18, 20, [](int x, int y) { return (x < 16 ? 1.0f : 4.0f) * (y < 16 ? 1.0f : 9.0f); });
    // Squares 1, 4, 9 and 36: key (1 * 4 * 9 * 36)^(1/4) = 1296^(1/4) = 6.
    EXPECT_NEAR(exposureOf(SampleBands(partial.data(), 18, 20, 1), 18), 0.64 / 6.0, 1e-6);
}

TEST(Exposure, DarkSquaresBadRadianceAndBlackFrames) {
    // Squares of 1, 1, 1 and 1e-5 (under 1e-4 of the mean square, 0.75): the dark one is left
    // out, key 1. NaN, Inf and negative radiance read as 0.
    auto samples = greyFrame(32, 32, [](int x, int y) { return x >= 16 && y >= 16 ? 1e-5f : 1.0f; });
    EXPECT_NEAR(exposureOf(SampleBands(samples.data(), 32, 32, 1), 32), 0.64, 1e-6);
    samples[channel::kDiffuse] = std::numeric_limits<float>::quiet_NaN();
    samples[kFeatureCount + channel::kDiffuse] = -5.0f;
    samples[2 * kFeatureCount + channel::kDiffuse] = std::numeric_limits<float>::infinity();
    const float withBad = exposureOf(SampleBands(samples.data(), 32, 32, 1), 32);
    EXPECT_TRUE(std::isfinite(withBad));
    EXPECT_GT(withBad, 0.64f);  // three red values of the first square now read 0: darker key
    const auto black = greyFrame(8, 8, [](int, int) { return 0.0f; });
    EXPECT_EQ(exposureOf(SampleBands(black.data(), 8, 8, 1), 8), 0.0f);
}

TEST(Embedding, RejectsBadLayers) {
    std::mt19937 rng(5);
    EXPECT_THROW(Embedding({}), Error);
    EXPECT_THROW(Embedding(randomLayers({17, 32}, rng)), Error);
    std::vector<DenseLayer> broken = randomLayers({18, 32, 32}, rng);
    broken[1].in = 31;
    EXPECT_THROW(Embedding{broken}, Error);
    broken = randomLayers({18, 32, 32}, rng);
    broken[0].weight.pop_back();
    EXPECT_THROW(Embedding{broken}, Error);
    broken = randomLayers({18, 32, 32}, rng);
    broken[1].bias.pop_back();
    EXPECT_THROW(Embedding{broken}, Error);
    const Embedding ok(randomLayers({18, 4}, rng));
    FeatureMap output;
    float sample[kFeatureCount] = {};
    EXPECT_THROW(ok.apply(sample, 1, 1, 0, 1.0f, output), Error);
    EXPECT_EQ(ok.apply(sample, 0, 5, 1, 1.0f, output), 0);
    EXPECT_EQ(output.size(), 0u);
}

TEST(FastLog1p, WithinFewUlps) {
    // Dense sweep over [0, 1e30] on a log scale plus exact edge values.
    std::vector<float> values = {0.0f,          1e-45f, 1e-38f,       1e-30f,       1e-8f, 5.9604645e-8f,
                                 1.1920929e-7f, 0.5f,   0.41421356f,  0.41421357f,  1.0f,  2.0f,
                                 3.0f,          1e7f,   1.6777216e7f, 3.4028235e38f};
    for (double e = -40; e <= 30; e += 1e-4) values.push_back(float(std::pow(10.0, e)));
    while (values.size() % 8 != 0) values.push_back(0.0f);
    double worst = 0.0;
    for (std::size_t i = 0; i < values.size(); i += 8) {
        Vec8f lanes;
        for (int l = 0; l < 8; ++l) lanes[l] = values[i + std::size_t(l)];
        const Vec8f logs = log1pNonNegative8(lanes);
        for (int l = 0; l < 8; ++l) {
            const double exact = std::log1p(double(lanes[l]));
            const float got = logs[l];
            if (exact == 0.0) {
                EXPECT_EQ(got, 0.0f);
                continue;
            }
            worst = std::max(worst, std::abs(got - exact) / exact);
        }
    }
    // 4e-7 is about 3.5 ulp: far inside the 1e-4 inference/training parity budget.
    EXPECT_LE(worst, 4e-7);
    RecordProperty("worstRelativeError", std::to_string(worst));
    std::printf("log1pNonNegative8 worst relative error %.3g\n", worst);
}

}  // namespace
}  // namespace affinity
