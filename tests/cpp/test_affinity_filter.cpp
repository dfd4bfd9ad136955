// The affinity filter (docs/MODEL.md sections 3, 6, 7): agreement with a naive double
// precision reference, the properties the maths implies (box filter, centre exclusion,
// constant radiance, no temporal contribution without valid history), bilinear warping, and
// results that do not depend on the thread count.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <utility>
#include <vector>

#include "affinity/error.h"
#include "kernels/affinity_filter.h"
#include "kernels/bilinear_warp.h"
#include "kernels/catmull_rom_warp.h"
#include "kernels/fast_exp.h"

namespace affinity {
namespace {

constexpr double kEpsilon = 1e-8;

FeatureMap randomMap(int height, int width, int channels, float low, float high, std::mt19937& rng) {
    FeatureMap map(height, width, channels);
    std::uniform_real_distribution<float> uniform(low, high);
    for (std::size_t i = 0; i < map.size(); ++i) map.data()[i] = uniform(rng);
    return map;
}

FeatureMap constantMap(int height, int width, int channels, float value) {
    FeatureMap map(height, width, channels);
    map.fill(value);
    return map;
}

bool bitwiseEqual(const FeatureMap& a, const FeatureMap& b) {
    return a.height() == b.height() && a.width() == b.width() && a.channels() == b.channels() &&
           std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

// All inputs of one filter call.
struct Scene {
    FeatureMap radiance, features, bandwidth, centre;
    FeatureMap temporalBandwidth, warpedOutput, warpedFeatures, warpedValid;
    KernelParams kernel() const { return {&features, &bandwidth, &centre}; }
};

// Features in [0, 1], a in [-2, 2] (so a^2 ||df||^2 stays in the range where weights are not
// negligible), c in [0.05, 1], the filtered signal (3 channels of radiance) in [0.01, 10];
// validity 0, 1 or fractional.
Scene randomScene(int height, int width, int features, std::mt19937& rng) {
    const int signalChannels = 3;
    Scene s;
    s.radiance = randomMap(height, width, signalChannels, 0.01f, 10.0f, rng);
    s.features = randomMap(height, width, features, 0.0f, 1.0f, rng);
    s.bandwidth = randomMap(height, width, 1, -2.0f, 2.0f, rng);
    s.centre = randomMap(height, width, 1, 0.05f, 1.0f, rng);
    s.temporalBandwidth = randomMap(height, width, 1, -2.0f, 2.0f, rng);
    s.warpedOutput = randomMap(height, width, signalChannels, 0.01f, 10.0f, rng);
    s.warpedFeatures = randomMap(height, width, features, 0.0f, 1.0f, rng);
    s.warpedValid = randomMap(height, width, 1, 0.0f, 1.0f, rng);
    for (std::size_t i = 0; i < s.warpedValid.size(); ++i) {
        float& v = s.warpedValid.data()[i];
        v = v < 0.4f ? 0.0f : (v < 0.8f ? 1.0f : v);
    }
    return s;
}

double squaredDistance(const FeatureMap& a, int ay, int ax, const FeatureMap& b, int by, int bx) {
    double sum = 0;
    for (int c = 0; c < a.channels(); ++c) {
        const double d = double(a.pixel(ay, ax)[c]) - double(b.pixel(by, bx)[c]);
        sum += d * d;
    }
    return sum;
}

double luminanceOf(const FeatureMap& map, int y, int x) {
    const float* rgb = map.pixel(y, x);
    return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
}

// docs/MODEL.md sections 6 and 7, literally, in double precision; with guardRatio > 0 the
// bright-history guard of section 10 too.
FeatureMap reference(const Scene& s, int tapSize, int dilation, bool temporal, double guardRatio = 0.0,
                     double guardFloor = 0.0) {
    const int height = s.radiance.height(), width = s.radiance.width(), radius = tapSize / 2;
    const int channels = s.radiance.channels();
    FeatureMap out(height, width, channels);
    for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) {
            std::vector<double> sum(std::size_t(channels), 0.0);
            double weights = 0;
            const double a = s.bandwidth.pixel(y, x)[0];
            for (int j = -radius; j <= radius; ++j) {
                for (int i = -radius; i <= radius; ++i) {
                    const int qx = x + dilation * i, qy = y + dilation * j;
                    if (qx < 0 || qy < 0 || qx >= width || qy >= height) continue;
                    const double w = (i == 0 && j == 0)
                                         ? double(s.centre.pixel(y, x)[0])
                                         : std::exp(-a * a * squaredDistance(s.features, y, x, s.features, qy, qx));
                    for (int c = 0; c < channels; ++c) sum[std::size_t(c)] += w * s.radiance.pixel(qy, qx)[c];
                    weights += w;
                }
            }
            if (temporal) {
                const double b = s.temporalBandwidth.pixel(y, x)[0];
                for (int j = -1; j <= 1; ++j) {
                    for (int i = -1; i <= 1; ++i) {
                        const int qx = x + i, qy = y + j;
                        if (qx < 0 || qy < 0 || qx >= width || qy >= height) continue;
                        if (guardRatio > 0.0 && luminanceOf(s.warpedOutput, qy, qx) >
                                                    guardRatio * (luminanceOf(s.radiance, y, x) + guardFloor))
                            continue;
                        const double w = s.warpedValid.pixel(qy, qx)[0] *
                                         std::exp(-b * b * squaredDistance(s.features, y, x, s.warpedFeatures, qy, qx));
                        for (int c = 0; c < channels; ++c) sum[std::size_t(c)] += w * s.warpedOutput.pixel(qy, qx)[c];
                        weights += w;
                    }
                }
            }
            for (int c = 0; c < channels; ++c) out.pixel(y, x)[c] = float(sum[std::size_t(c)] / (kEpsilon + weights));
        }
    }
    return out;
}

FeatureMap run(const Scene& s, int tapSize, int dilation, bool temporal) {
    FeatureMap out;
    if (temporal) {
        affinityFilterTemporal(s.radiance, s.kernel(), tapSize, dilation, s.temporalBandwidth, s.warpedOutput,
                               s.warpedFeatures, s.warpedValid, out);
    } else {
        affinityFilter(s.radiance, s.kernel(), tapSize, dilation, out);
    }
    return out;
}

double maxRelativeDifference(const FeatureMap& actual, const FeatureMap& expected) {
    EXPECT_EQ(actual.height(), expected.height());
    EXPECT_EQ(actual.width(), expected.width());
    EXPECT_EQ(actual.channels(), expected.channels());
    double worst = 0;
    for (std::size_t i = 0; i < expected.size(); ++i) {
        const double e = expected.data()[i], a = actual.data()[i];
        const double difference = std::abs(a - e) / std::max(std::abs(e), 1e-6);
        worst = std::isnan(a) ? INFINITY : std::max(worst, difference);
    }
    return worst;
}

struct Size {
    int height, width;
};
const Size kSizes[] = {{1, 1}, {7, 13}, {64, 48}};

TEST(FastExp, MaxRelativeErrorOnTheUsedRange) {
    double worst = 0, worstAt = 0;
    const int count = 2000000;
    for (int k = 0; k < count; k += 8) {
        Vec8f x;
        for (int l = 0; l < 8; ++l) x[l] = -87.0f * float(k + l) / float(count);
        const Vec8f y = fastExpNonPositive(x);
        for (int l = 0; l < 8; ++l) {
            const double exact = std::exp(double(x[l]));
            const double error = std::abs(double(y[l]) - exact) / exact;
            if (error > worst) worst = error, worstAt = x[l];
        }
    }
    std::printf("fastExpNonPositive: max relative error %.3g at x = %.6g over [-87, 0]\n", worst, worstAt);
    EXPECT_LT(worst, 1e-6);
    EXPECT_EQ(fastExpNonPositive(broadcast8(0.0f))[0], 1.0f);
    EXPECT_EQ(fastExpNonPositive(broadcast8(-0.0f))[0], 1.0f);
    // Below the range the weight is exactly zero (never a denormal number).
    EXPECT_EQ(fastExpNonPositive(broadcast8(-87.5f))[0], 0.0f);
    EXPECT_EQ(fastExpNonPositive(broadcast8(-1e30f))[0], 0.0f);
    EXPECT_EQ(fastExpNonPositive(broadcast8(-INFINITY))[0], 0.0f);
}

TEST(FastSigmoid, MaxRelativeErrorAndSymmetry) {
    double worst = 0;
    for (int k = -400000; k < 400000; k += 8) {
        Vec8f x;
        for (int l = 0; l < 8; ++l) x[l] = 1e-4f * float(k + l);  // [-40, 40]
        const Vec8f y = fastSigmoid(x), mirrored = fastSigmoid(-x);
        for (int l = 0; l < 8; ++l) {
            const double exact = 1.0 / (1.0 + std::exp(-double(x[l])));
            worst = std::max(worst, std::abs(double(y[l]) - exact) / exact);
            EXPECT_NEAR(double(y[l]) + double(mirrored[l]), 1.0, 1e-6) << x[l];
        }
    }
    std::printf("fastSigmoid: max relative error %.3g over [-40, 40]\n", worst);
    EXPECT_LT(worst, 1e-6);
    EXPECT_EQ(fastSigmoid(broadcast8(0.0f))[0], 0.5f);
    EXPECT_EQ(fastSigmoid(broadcast8(1e30f))[0], 1.0f);
    EXPECT_EQ(fastSigmoid(broadcast8(-1e30f))[0], 0.0f);
}

TEST(AffinityFilter, MatchesDoubleReference) {
    std::mt19937 rng(1);
    for (const Size size : kSizes) {
        for (const int tapSize : {3, 5, 7}) {
            for (const int dilation : {1, 2, 4}) {
                const Scene s = randomScene(size.height, size.width, 8, rng);
                const double difference =
                    maxRelativeDifference(run(s, tapSize, dilation, false), reference(s, tapSize, dilation, false));
                EXPECT_LT(difference, 1e-5)
                    << size.height << "x" << size.width << " T=" << tapSize << " d=" << dilation;
            }
        }
    }
}

TEST(AffinityFilter, TemporalMatchesDoubleReference) {
    std::mt19937 rng(2);
    for (const Size size : kSizes) {
        for (const int tapSize : {3, 5, 7}) {
            for (const int dilation : {1, 2, 4}) {
                const Scene s = randomScene(size.height, size.width, 8, rng);
                const double difference =
                    maxRelativeDifference(run(s, tapSize, dilation, true), reference(s, tapSize, dilation, true));
                EXPECT_LT(difference, 1e-5)
                    << size.height << "x" << size.width << " T=" << tapSize << " d=" << dilation;
            }
        }
    }
}

TEST(AffinityFilter, EveryFeatureCountMatchesReference) {
    // 1..16 have specialised kernels, 17 and 24 take the generic one; T = 1 has no spatial
    // neighbours at all.
    std::mt19937 rng(3);
    for (const int features : {1, 2, 3, 5, 8, 12, 16, 17, 24}) {
        for (const bool temporal : {false, true}) {
            for (const int tapSize : {1, 5}) {
                Scene s = randomScene(19, 23, features, rng);
                // Keep a^2 ||df||^2 moderate however many features there are.
                for (std::size_t i = 0; i < s.bandwidth.size(); ++i)
                    s.bandwidth.data()[i] /= std::sqrt(float(features));
                const double difference =
                    maxRelativeDifference(run(s, tapSize, 2, temporal), reference(s, tapSize, 2, temporal));
                EXPECT_LT(difference, 1e-5) << "F=" << features << " temporal=" << temporal << " T=" << tapSize;
            }
        }
    }
}

TEST(AffinityFilter, ZeroBandwidthAndUnitCentreIsAnExactBoxFilter) {
    std::mt19937 rng(4);
    std::uniform_int_distribution<int> integers(0, 100);
    for (const Size size : kSizes) {
        for (const int tapSize : {3, 5, 7}) {
            for (const int dilation : {1, 2, 4}) {
                Scene s = randomScene(size.height, size.width, 8, rng);
                // Integer radiance: every float sum is exact, so the mean is the correctly
                // rounded quotient.
                for (std::size_t i = 0; i < s.radiance.size(); ++i) s.radiance.data()[i] = float(integers(rng));
                s.bandwidth.fill(0.0f);
                s.centre.fill(1.0f);
                const FeatureMap out = run(s, tapSize, dilation, false);
                const int radius = tapSize / 2;
                for (int y = 0; y < size.height; ++y) {
                    for (int x = 0; x < size.width; ++x) {
                        for (int c = 0; c < 3; ++c) {
                            double sum = 0;
                            int count = 0;
                            for (int j = -radius; j <= radius; ++j) {
                                for (int i = -radius; i <= radius; ++i) {
                                    const int qx = x + dilation * i, qy = y + dilation * j;
                                    if (qx < 0 || qy < 0 || qx >= size.width || qy >= size.height) continue;
                                    sum += s.radiance.pixel(qy, qx)[c];
                                    ++count;
                                }
                            }
                            ASSERT_EQ(out.pixel(y, x)[c], float(sum / count))
                                << "pixel " << x << "," << y << " T=" << tapSize << " d=" << dilation;
                        }
                    }
                }
            }
        }
    }
}

TEST(AffinityFilter, ZeroCentreWeightGivesTheNeighboursWeightedValue) {
    // The centre pixel's features are far from its neighbours' (weights 1e-4 .. 1e-2): with
    // c = 0 the result is the neighbours' weighted mean, not the centre's own radiance.
    std::mt19937 rng(5);
    Scene s = randomScene(5, 5, 8, rng);
    s.centre.fill(0.0f);
    s.bandwidth.fill(3.0f);  // a^2 = 9
    for (int y = 0; y < 5; ++y) {
        for (int x = 0; x < 5; ++x) {
            for (int c = 0; c < 8; ++c) s.features.pixel(y, x)[c] = 0.0f;
        }
    }
    // ||df||^2 between 0.5 and 1: exp(-9 * ||df||^2) between 1.2e-4 and 1.1e-2.
    std::uniform_real_distribution<float> spread(0.25f, 0.35f);
    for (int c = 0; c < 8; ++c) s.features.pixel(2, 2)[c] = spread(rng);
    for (int c = 0; c < 3; ++c) s.radiance.pixel(2, 2)[c] = 1000.0f;
    const FeatureMap out = run(s, 5, 1, false);
    double sum[3] = {0, 0, 0}, weights = 0;
    for (int y = 0; y < 5; ++y) {
        for (int x = 0; x < 5; ++x) {
            if (x == 2 && y == 2) continue;
            const double w = std::exp(-9.0 * squaredDistance(s.features, 2, 2, s.features, y, x));
            for (int c = 0; c < 3; ++c) sum[c] += w * s.radiance.pixel(y, x)[c];
            weights += w;
        }
    }
    ASSERT_GT(weights, 1e-3);
    for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(out.pixel(2, 2)[c], sum[c] / weights, 1e-4 * sum[c] / weights);
        EXPECT_LT(out.pixel(2, 2)[c], 10.0f);  // nothing of the centre's 1000
    }
}

TEST(AffinityFilter, ZeroCentreWeightRemovesAnIsolatedFirefly) {
    Scene s;
    s.radiance = constantMap(9, 9, 3, 1.0f);
    for (int c = 0; c < 3; ++c) s.radiance.pixel(4, 4)[c] = 1000.0f;
    s.features = constantMap(9, 9, 8, 0.5f);
    s.bandwidth = constantMap(9, 9, 1, 1.0f);
    s.centre = constantMap(9, 9, 1, 1.0f);
    s.centre.pixel(4, 4)[0] = 0.0f;
    const FeatureMap out = run(s, 5, 1, false);
    for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(out.pixel(4, 4)[c], 1.0f);
    // With the centre kept the firefly survives, spread over its 25 taps.
    s.centre.fill(1.0f);
    const FeatureMap kept = run(s, 5, 1, false);
    EXPECT_NEAR(kept.pixel(4, 4)[0], (1000.0f + 24.0f) / 25.0f, 1e-3f);
}

TEST(AffinityFilter, ConstantRadianceStaysConstant) {
    std::mt19937 rng(6);
    const float levels[3] = {0.25f, 3.0f, 1234.5f};
    for (const bool temporal : {false, true}) {
        for (const int dilation : {1, 4}) {
            Scene s = randomScene(31, 29, 8, rng);
            s.bandwidth = randomMap(31, 29, 1, -50.0f, 50.0f, rng);  // any bandwidth, huge included
            s.temporalBandwidth = randomMap(31, 29, 1, -50.0f, 50.0f, rng);
            s.features = randomMap(31, 29, 8, -10.0f, 10.0f, rng);
            for (int y = 0; y < 31; ++y) {
                for (int x = 0; x < 29; ++x) {
                    for (int c = 0; c < 3; ++c) {
                        s.radiance.pixel(y, x)[c] = levels[c];
                        s.warpedOutput.pixel(y, x)[c] = levels[c];
                    }
                }
            }
            const FeatureMap out = run(s, 5, dilation, temporal);
            for (int y = 0; y < 31; ++y) {
                for (int x = 0; x < 29; ++x) {
                    for (int c = 0; c < 3; ++c) {
                        ASSERT_NEAR(out.pixel(y, x)[c], levels[c], 1e-5 * levels[c]) << x << "," << y;
                    }
                }
            }
        }
    }
}

TEST(AffinityFilter, TemporalWithoutValidHistoryEqualsSpatial) {
    std::mt19937 rng(7);
    for (const Size size : kSizes) {
        for (const int tapSize : {3, 5}) {
            Scene s = randomScene(size.height, size.width, 8, rng);
            s.warpedValid.fill(0.0f);
            EXPECT_TRUE(bitwiseEqual(run(s, tapSize, 2, true), run(s, tapSize, 2, false)))
                << size.height << "x" << size.width;
        }
    }
}

TEST(AffinityFilter, InstructionSetsAgreeBitwise) {
    // The reference tests run the default (widest) strips; this holds the 8-lane strips to the
    // 16-lane ones bit for bit, spatial and temporal, widths that end inside a strip of either
    // width, specialised and generic feature counts.
    if (!cpuHasAvx512()) GTEST_SKIP() << "this CPU has no AVX-512: only the 8-lane strips run here";
    std::mt19937 rng(31);
    for (const Size size : {Size{9, 200}, Size{5, 129}, Size{3, 7}})
        for (const int features : {8, 3, 17})
            for (const bool temporal : {false, true}) {
                SCOPED_TRACE(std::to_string(size.height) + "x" + std::to_string(size.width) +
                             " F=" + std::to_string(features) + (temporal ? " temporal" : ""));
                Scene s = randomScene(size.height, size.width, features, rng);
                const TemporalTaps taps{&s.temporalBandwidth, &s.warpedOutput, &s.warpedFeatures, &s.warpedValid};
                FeatureMap narrow(size.height, size.width, 3), wide(size.height, size.width, 3);
                affinityFilterRows(s.radiance, s.kernel(), 5, 2, temporal ? &taps : nullptr, size.height, 0,
                                   size.height, narrow, ConvIsa::Avx2);
                affinityFilterRows(s.radiance, s.kernel(), 5, 2, temporal ? &taps : nullptr, size.height, 0,
                                   size.height, wide, ConvIsa::Avx512);
                ASSERT_EQ(std::memcmp(narrow.data(), wide.data(), narrow.size() * sizeof(float)), 0);
            }
}

TEST(AffinityFilter, ResultsDoNotDependOnTheThreadCount) {
    std::mt19937 rng(8);
    const Scene s = randomScene(97, 75, 8, rng);
    const int before = omp_get_max_threads();
    omp_set_num_threads(1);
    const FeatureMap spatialOne = run(s, 5, 2, false), temporalOne = run(s, 7, 4, true);
    omp_set_num_threads(2);
    const FeatureMap spatialTwo = run(s, 5, 2, false), temporalTwo = run(s, 7, 4, true);
    omp_set_num_threads(3);
    const FeatureMap spatialThree = run(s, 5, 2, false);
    omp_set_num_threads(before);
    EXPECT_TRUE(bitwiseEqual(spatialOne, spatialTwo));
    EXPECT_TRUE(bitwiseEqual(spatialOne, spatialThree));
    EXPECT_TRUE(bitwiseEqual(temporalOne, temporalTwo));
}

TEST(AffinityFilter, OutputMayBeTheRadianceBuffer) {
    std::mt19937 rng(9);
    Scene s = randomScene(20, 30, 8, rng);
    const FeatureMap separate = run(s, 5, 2, false);
    affinityFilter(s.radiance, s.kernel(), 5, 2, s.radiance);
    EXPECT_TRUE(bitwiseEqual(s.radiance, separate));
}

// Rows [begin, end) of `map` copied into a ring of `rows` rows (image row y at row y % rows).
FeatureMap ringOf(const FeatureMap& map, int rows, int begin, int end) {
    FeatureMap ring(rows, map.width(), map.channels());
    ring.fill(std::nanf(""));  // a row read that the ring does not hold poisons the result
    for (int y = std::max(0, begin); y < std::min(map.height(), end); ++y)
        std::copy(map.pixel(y, 0), map.pixel(y, 0) + std::size_t(map.width()) * map.channels(),
                  ring.pixel(y % rows, 0));
    return ring;
}

// The bright-history guard (docs/MODEL.md section 10): history up to 100x brighter than the
// filtered signal, so that many taps exceed the bound and many do not.
TEST(AffinityFilter, BrightHistoryGuardMatchesDoubleReference) {
    std::mt19937 rng(31);
    const int height = 23, width = 41, tapSize = 5, dilation = 2;
    Scene s = randomScene(height, width, 8, rng);
    s.warpedOutput = randomMap(height, width, 3, 0.01f, 100.0f, rng);
    const float ratio = 8.0f, floor = 0.5f;
    const TemporalTaps guarded{&s.temporalBandwidth, &s.warpedOutput, &s.warpedFeatures, &s.warpedValid, ratio, floor};
    FeatureMap out(height, width, 3);
    affinityFilterRows(s.radiance, s.kernel(), tapSize, dilation, &guarded, height, 0, height, out);
    EXPECT_LT(maxRelativeDifference(out, reference(s, tapSize, dilation, true, ratio, floor)), 1e-5);
    // The guard took history away from some pixels and not from others.
    const FeatureMap unguarded = run(s, tapSize, dilation, true);
    int changed = 0;
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) changed += std::fabs(out.pixel(y, x)[0] - unguarded.pixel(y, x)[0]) > 1e-3f;
    EXPECT_GT(changed, height * width / 10);
    EXPECT_LT(changed, height * width);
}

// A dark pixel beside a lamp's previous output: the guard keeps the pixel's own history and drops
// the lamp's.
TEST(AffinityFilter, BrightHistoryGuardDropsALampsHistoryBesideADarkPixel) {
    const int height = 3, width = 3;
    Scene s;
    s.radiance = constantMap(height, width, 3, 0.1f);
    s.features = constantMap(height, width, 4, 0.5f);
    s.bandwidth = constantMap(height, width, 1, 1.0f);
    s.centre = constantMap(height, width, 1, 1.0f);
    s.temporalBandwidth = constantMap(height, width, 1, 1.0f);
    s.warpedOutput = constantMap(height, width, 3, 0.1f);
    for (int x = 0; x < width; ++x) std::fill_n(s.warpedOutput.pixel(0, x), 3, 50.0f);  // the lamp, a row above
    s.warpedFeatures = constantMap(height, width, 4, 0.5f);
    s.warpedValid = constantMap(height, width, 1, 1.0f);
    const TemporalTaps guarded{&s.temporalBandwidth, &s.warpedOutput, &s.warpedFeatures, &s.warpedValid, 8.0f, 0.1f};
    FeatureMap out(height, width, 3);
    affinityFilterRows(s.radiance, s.kernel(), 3, 1, &guarded, height, 0, height, out);
    EXPECT_NEAR(out.pixel(1, 1)[0], 0.1f, 1e-6f);                           // 8 x (0.1 + 0.1) = 1.6 < 50
    EXPECT_NEAR(run(s, 3, 1, true).pixel(1, 1)[0], 151.5f / 18.0f, 1e-4f);  // unguarded: (3 x 50 + 15 x 0.1) / 18
    EXPECT_NEAR(out.pixel(0, 1)[0], 0.1f, 1e-6f);  // the lamp's row: dark now, its history dropped
}

TEST(AffinityFilter, BandsThroughRingsEqualTheWholeImage) {
    std::mt19937 rng(21);
    const int height = 37, width = 29, band = 5, tapSize = 5, dilation = 2;
    Scene s = randomScene(height, width, 8, rng);
    for (bool temporal : {false, true}) {
        const FeatureMap whole = run(s, tapSize, dilation, temporal);
        const int reach = (tapSize / 2) * dilation;
        const int rows = band + 2 * reach;
        for (int begin = 0; begin < height; begin += band) {
            const int end = std::min(height, begin + band);
            auto ring = [&](const FeatureMap& map) { return ringOf(map, rows, begin - reach, end + reach); };
            const FeatureMap radiance = ring(s.radiance), features = ring(s.features), bandwidth = ring(s.bandwidth),
                             centre = ring(s.centre), temporalBandwidth = ring(s.temporalBandwidth),
                             warpedOutput = ring(s.warpedOutput), warpedFeatures = ring(s.warpedFeatures),
                             warpedValid = ring(s.warpedValid);
            const TemporalTaps taps{&temporalBandwidth, &warpedOutput, &warpedFeatures, &warpedValid};
            FeatureMap out(band, width, 3);
            affinityFilterRows(radiance, {&features, &bandwidth, &centre}, tapSize, dilation,
                               temporal ? &taps : nullptr, height, begin, end, out);
            for (int y = begin; y < end; ++y)
                ASSERT_EQ(std::memcmp(out.pixel(y % band, 0), whole.pixel(y, 0), sizeof(float) * 3 * width), 0)
                    << "row " << y << (temporal ? " (temporal)" : "");
        }
    }
}

TEST(AffinityFilter, RejectsARingTooShortForTheRowsItReads) {
    std::mt19937 rng(22);
    Scene s = randomScene(30, 9, 8, rng);
    const FeatureMap shortRadiance = ringOf(s.radiance, 8, 0, 8);
    FeatureMap out(30, 9, 3);
    // Rows 0..4 with dilation 2 read rows -4..8: 13 rows, more than the ring's 8.
    EXPECT_THROW(affinityFilterRows(shortRadiance, s.kernel(), 5, 2, nullptr, 30, 0, 5, out), Error);
    EXPECT_THROW(affinityFilterRows(s.radiance, s.kernel(), 5, 2, nullptr, 30, 0, 5, s.radiance), Error);
    EXPECT_THROW(affinityFilterRows(s.radiance, s.kernel(), 5, 2, nullptr, 30, 25, 31, out), Error);
}

TEST(AffinityFilter, EmptyImage) {
    Scene s;
    s.radiance = FeatureMap(0, 0, 3);
    s.features = FeatureMap(0, 0, 8);
    s.bandwidth = FeatureMap(0, 0, 1);
    s.centre = FeatureMap(0, 0, 1);
    FeatureMap out;
    affinityFilter(s.radiance, s.kernel(), 5, 1, out);
    EXPECT_TRUE(out.empty());
}

TEST(AffinityFilter, RejectsInconsistentInputs) {
    std::mt19937 rng(10);
    Scene s = randomScene(8, 9, 8, rng);
    FeatureMap out;
    EXPECT_THROW(affinityFilter(s.radiance, s.kernel(), 4, 1, out), Error);
    EXPECT_THROW(affinityFilter(s.radiance, s.kernel(), 5, 0, out), Error);
    const FeatureMap wrongSize = randomMap(8, 10, 1, 0, 1, rng);
    EXPECT_THROW(affinityFilter(s.radiance, {&s.features, &wrongSize, &s.centre}, 5, 1, out), Error);
    const FeatureMap twoChannels = randomMap(8, 9, 2, 0, 1, rng);
    EXPECT_THROW(affinityFilter(twoChannels, s.kernel(), 5, 1, out), Error);
    const FeatureMap otherFeatures = randomMap(8, 9, 7, 0, 1, rng);
    EXPECT_THROW(affinityFilterTemporal(s.radiance, s.kernel(), 5, 1, s.temporalBandwidth, s.warpedOutput,
                                        otherFeatures, s.warpedValid, out),
                 Error);
    // The signal is RGB radiance; a warped output must have its channels.
    const FeatureMap sixChannels = randomMap(8, 9, 6, 0, 1, rng);
    EXPECT_THROW(affinityFilter(sixChannels, s.kernel(), 5, 1, out), Error);
    EXPECT_THROW(affinityFilterTemporal(s.radiance, s.kernel(), 5, 1, s.temporalBandwidth, sixChannels,
                                        s.warpedFeatures, s.warpedValid, out),
                 Error);
    // The bright-history guard's bound must be a finite, non-negative ratio and floor.
    FeatureMap rows(8, 9, 3);
    for (const auto& [ratio, floor] :
         {std::pair{-1.0f, 0.0f}, std::pair{8.0f, -0.1f}, std::pair{std::numeric_limits<float>::infinity(), 0.0f}}) {
        const TemporalTaps taps{&s.temporalBandwidth, &s.warpedOutput, &s.warpedFeatures, &s.warpedValid, ratio, floor};
        EXPECT_THROW(affinityFilterRows(s.radiance, s.kernel(), 5, 1, &taps, 8, 0, 8, rows), Error);
    }
}

// Warping.

std::vector<float> uniformMotion(int height, int width, float mx, float my) {
    std::vector<float> motion(std::size_t(height) * width * 2);
    for (std::size_t i = 0; i < motion.size(); i += 2) {
        motion[i] = mx;
        motion[i + 1] = my;
    }
    return motion;
}

// Motion vectors drawn uniformly in [-range, range] pixels, both coordinates.
std::vector<float> randomMotion(int height, int width, float range, std::mt19937& rng) {
    std::vector<float> motion(std::size_t(height) * width * 2);
    std::uniform_real_distribution<float> shift(-range, range);
    for (float& m : motion) m = shift(rng);
    return motion;
}

TEST(WarpBilinear, ZeroMotionIsTheIdentity) {
    std::mt19937 rng(11);
    const FeatureMap previous = randomMap(13, 17, 5, -3.0f, 3.0f, rng);
    FeatureMap out;
    warpBilinear(previous, uniformMotion(13, 17, 0, 0).data(), out);
    EXPECT_TRUE(bitwiseEqual(out, previous));
}

TEST(WarpBilinear, IntegerMotionShiftsWithBorderClamping) {
    std::mt19937 rng(12);
    const FeatureMap previous = randomMap(11, 14, 3, -3.0f, 3.0f, rng);
    for (const auto& [mx, my] : std::vector<std::pair<int, int>>{{2, 0}, {0, -3}, {-5, 4}, {20, -20}}) {
        FeatureMap out;
        warpBilinear(previous, uniformMotion(11, 14, float(mx), float(my)).data(), out);
        for (int y = 0; y < 11; ++y) {
            for (int x = 0; x < 14; ++x) {
                const int sx = std::clamp(x + mx, 0, 13), sy = std::clamp(y + my, 0, 10);
                for (int c = 0; c < 3; ++c) {
                    ASSERT_EQ(out.pixel(y, x)[c], previous.pixel(sy, sx)[c])
                        << mx << "," << my << " at " << x << "," << y;
                }
            }
        }
    }
}

TEST(WarpBilinear, LinearRampIsReproducedExactly) {
    // v = 2x + 3y + 1 with dyadic motion: every bilinear product and sum is exact in float.
    const int height = 9, width = 12;
    FeatureMap previous(height, width, 2);
    for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) {
            previous.pixel(y, x)[0] = float(2 * x + 3 * y + 1);
            previous.pixel(y, x)[1] = float(-x + 5 * y);
        }
    }
    std::vector<float> motion(std::size_t(height) * width * 2);
    const float fractions[] = {0.25f, -0.5f, 0.75f, 1.125f, -2.375f, 0.0f};
    for (std::size_t i = 0; i < motion.size(); ++i) motion[i] = fractions[i % 6];
    FeatureMap out;
    warpBilinear(previous, motion.data(), out);
    for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) {
            const float* m = motion.data() + 2 * (std::size_t(y) * width + x);
            const float sx = float(x) + m[0], sy = float(y) + m[1];
            if (sx < 0 || sy < 0 || sx > float(width - 1) || sy > float(height - 1)) continue;
            EXPECT_EQ(out.pixel(y, x)[0], 2 * sx + 3 * sy + 1) << x << "," << y;
            EXPECT_EQ(out.pixel(y, x)[1], -sx + 5 * sy) << x << "," << y;
        }
    }
}

TEST(WarpBilinear, ClampsTheContinuousPositionAtTheBorder) {
    FeatureMap previous(2, 3, 1);
    const float values[6] = {1, 2, 4, 8, 16, 32};
    std::memcpy(previous.data(), values, sizeof values);
    FeatureMap out;
    // From pixel (0, 0): half a pixel left of the image reads the border column only.
    warpBilinear(previous, uniformMotion(2, 3, -0.5f, 0.5f).data(), out);
    EXPECT_EQ(out.pixel(0, 0)[0], (1.0f + 8.0f) / 2);
    // From pixel (2, 1): beyond the bottom right corner reads the corner.
    warpBilinear(previous, uniformMotion(2, 3, 0.75f, 0.25f).data(), out);
    EXPECT_EQ(out.pixel(1, 2)[0], 32.0f);
    // Non-finite and huge motion stays defined and clamps.
    std::vector<float> motion = uniformMotion(2, 3, NAN, INFINITY);
    motion[2] = -1e30f;
    warpBilinear(previous, motion.data(), out);
    for (std::size_t i = 0; i < out.size(); ++i) EXPECT_TRUE(std::isfinite(out.data()[i]));
}

// As the Catmull-Rom warp and the training framework's warps read it.
TEST(WarpBilinear, NanMotionReadsAsNoMotionAndHugeMotionClampsToTheBorder) {
    std::mt19937 rng(59);
    const FeatureMap previous = randomMap(7, 9, 3, -3.0f, 3.0f, rng);
    std::vector<float> motion = uniformMotion(7, 9, 0.25f, 0.0f);
    motion[2 * (3 * 9 + 4)] = std::nanf("");      // x NaN: no motion in x
    motion[2 * (2 * 9 + 6) + 1] = std::nanf("");  // y NaN: x still moves a quarter pixel
    motion[2 * (5 * 9 + 2) + 1] = 1e30f;
    motion[2 * (1 * 9 + 1)] = -std::numeric_limits<float>::infinity();
    FeatureMap out;
    warpBilinear(previous, motion.data(), out);
    for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(out.pixel(3, 4)[c], previous.pixel(3, 4)[c]);
        EXPECT_FLOAT_EQ(out.pixel(2, 6)[c], 0.75f * previous.pixel(2, 6)[c] + 0.25f * previous.pixel(2, 7)[c]);
        EXPECT_FLOAT_EQ(out.pixel(5, 2)[c], 0.75f * previous.pixel(6, 2)[c] + 0.25f * previous.pixel(6, 3)[c]);
        EXPECT_EQ(out.pixel(1, 1)[c], previous.pixel(1, 0)[c]);
    }
}

TEST(WarpBilinear, RowsIntoARingEqualTheWholeImage) {
    std::mt19937 rng(23);
    const int height = 23, width = 19;
    const FeatureMap previous = randomMap(height, width, 5, -3.0f, 3.0f, rng);
    const std::vector<float> motion = randomMotion(height, width, 6.0f, rng);
    FeatureMap whole;
    warpBilinear(previous, motion.data(), whole);
    FeatureMap ring(4, width, 5);
    for (int begin = 0; begin < height; begin += 4) {
        const int end = std::min(height, begin + 4);
        warpBilinearRows(previous, motion.data(), begin, end, ring);
        for (int y = begin; y < end; ++y)
            ASSERT_EQ(std::memcmp(ring.pixel(y % 4, 0), whole.pixel(y, 0), sizeof(float) * 5 * width), 0)
                << "row " << y;
    }
    FeatureMap tooShort(3, width, 5);
    EXPECT_THROW(warpBilinearRows(previous, motion.data(), 0, 4, tooShort), Error);
}

TEST(WarpBilinear, ResultsDoNotDependOnTheThreadCount) {
    std::mt19937 rng(13);
    const FeatureMap previous = randomMap(57, 41, 8, -3.0f, 3.0f, rng);
    const std::vector<float> motion = randomMotion(57, 41, 6.0f, rng);
    const int before = omp_get_max_threads();
    FeatureMap one, two;
    omp_set_num_threads(1);
    warpBilinear(previous, motion.data(), one);
    omp_set_num_threads(2);
    warpBilinear(previous, motion.data(), two);
    omp_set_num_threads(before);
    EXPECT_TRUE(bitwiseEqual(one, two));
}

// ---- the sharp warp of the radiance (catmull_rom_warp.h) --------------------------------

// The Catmull-Rom spline through p0..p3 at t in [0, 1] in its polynomial form (not the tap
// weights the warp uses), in double.
double catmullRom(double p0, double p1, double p2, double p3, double t) {
    return 0.5 *
           (2 * p1 + (p2 - p0) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t * t + (3 * p1 - p0 - 3 * p2 + p3) * t * t * t);
}

TEST(WarpCatmullRom, IntegerMotionShiftsWithBorderClamping) {
    std::mt19937 rng(41);
    const FeatureMap previous = randomMap(11, 14, 3, -3.0f, 3.0f, rng);
    for (const auto& [mx, my] : std::vector<std::pair<int, int>>{{0, 0}, {2, 0}, {0, -3}, {-5, 4}, {20, -20}}) {
        FeatureMap out;
        warpCatmullRom(previous, uniformMotion(11, 14, float(mx), float(my)).data(), out);
        for (int y = 0; y < 11; ++y)
            for (int x = 0; x < 14; ++x) {
                const int sx = std::clamp(x + mx, 0, 13), sy = std::clamp(y + my, 0, 10);
                for (int c = 0; c < 3; ++c)
                    ASSERT_EQ(out.pixel(y, x)[c], previous.pixel(sy, sx)[c])
                        << mx << "," << my << " at " << x << "," << y;
            }
    }
}

TEST(WarpCatmullRom, IsTheClampedBicubicSplineOfTheSixteenTaps) {
    std::mt19937 rng(43);
    const int height = 13, width = 16, channels = 5;  // 5: the generic channel loop
    for (const int count : {3, channels}) {
        const FeatureMap previous = randomMap(height, width, count, -2.0f, 3.0f, rng);
        const std::vector<float> motion = randomMotion(height, width, 7.0f, rng);
        FeatureMap out;
        warpCatmullRom(previous, motion.data(), out);
        auto at = [&](int y, int x, int c) {
            return double(previous.pixel(std::clamp(y, 0, height - 1), std::clamp(x, 0, width - 1))[c]);
        };
        int clamped = 0;
        for (int y = 0; y < height; ++y)
            for (int x = 0; x < width; ++x) {
                const float* m = &motion[2 * (std::size_t(y) * width + x)];
                const double px = std::clamp(double(x) + double(m[0]), 0.0, double(width - 1));
                const double py = std::clamp(double(y) + double(m[1]), 0.0, double(height - 1));
                const int x0 = int(std::floor(px)), y0 = int(std::floor(py));
                for (int c = 0; c < count; ++c) {
                    double rows[4];
                    for (int j = 0; j < 4; ++j)
                        rows[j] = catmullRom(at(y0 - 1 + j, x0 - 1, c), at(y0 - 1 + j, x0, c),
                                             at(y0 - 1 + j, x0 + 1, c), at(y0 - 1 + j, x0 + 2, c), px - x0);
                    const double spline = catmullRom(rows[0], rows[1], rows[2], rows[3], py - y0);
                    const double low =
                        std::min({at(y0, x0, c), at(y0, x0 + 1, c), at(y0 + 1, x0, c), at(y0 + 1, x0 + 1, c)});
                    const double high =
                        std::max({at(y0, x0, c), at(y0, x0 + 1, c), at(y0 + 1, x0, c), at(y0 + 1, x0 + 1, c)});
                    clamped += spline < low || spline > high;
                    ASSERT_NEAR(out.pixel(y, x)[c], std::clamp(spline, low, high), 2e-5)
                        << x << "," << y << " channel " << c;
                }
            }
        EXPECT_GT(clamped, 0) << "random data should exercise the clamp";
    }
}

TEST(WarpCatmullRom, StaysInsideTheRangeOfTheNearestTaps) {
    // A hard edge between 0 and 1 moved by fractions of a pixel: the cubic alone would ring
    // below 0 and above 1; radiance must not turn negative.
    const int height = 6, width = 20;
    FeatureMap previous(height, width, 3);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x)
            for (int c = 0; c < 3; ++c) previous.pixel(y, x)[c] = x < 10 ? 0.0f : 1.0f;
    for (const float mx : {0.25f, 0.5f, 0.75f, -0.3f}) {
        FeatureMap out;
        warpCatmullRom(previous, uniformMotion(height, width, mx, 0.4f).data(), out);
        for (int x = 0; x < width; ++x) {
            const float v = out.pixel(3, x)[0];
            EXPECT_GE(v, 0.0f) << mx << " at " << x;
            EXPECT_LE(v, 1.0f) << mx << " at " << x;
        }
    }
}

TEST(WarpCatmullRom, KeepsFineDetailThatBilinearBlurs) {
    // Stripes with a 4-pixel period moved half a pixel and back, as a history is resampled
    // every frame: bilinear halves their contrast, Catmull-Rom keeps most of it.
    const int height = 4, width = 64;
    FeatureMap previous(height, width, 3);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x)
            for (int c = 0; c < 3; ++c) previous.pixel(y, x)[c] = 1.0f + std::sin(1.5707963f * float(x) + 0.4f);
    auto roundTripError = [&](auto warp) {
        FeatureMap there, back;
        warp(previous, uniformMotion(height, width, 0.5f, 0.0f).data(), there);
        warp(there, uniformMotion(height, width, -0.5f, 0.0f).data(), back);
        double error = 0.0;
        for (int x = 8; x < width - 8; ++x) error += std::abs(back.pixel(2, x)[0] - previous.pixel(2, x)[0]);
        return error / (width - 16);
    };
    const double bilinear =
        roundTripError([](const FeatureMap& p, const float* m, FeatureMap& o) { warpBilinear(p, m, o); });
    const double catmullRom =
        roundTripError([](const FeatureMap& p, const float* m, FeatureMap& o) { warpCatmullRom(p, m, o); });
    EXPECT_GT(bilinear, 0.25);  // mean |sin| is 0.64: half the contrast lost
    EXPECT_LT(catmullRom, 0.5 * bilinear) << "bilinear " << bilinear;
}

TEST(WarpCatmullRom, NanMotionReadsAsNoMotionAndHugeMotionClampsToTheBorder) {
    std::mt19937 rng(47);
    const FeatureMap previous = randomMap(7, 9, 3, -3.0f, 3.0f, rng);
    std::vector<float> motion = uniformMotion(7, 9, 0.0f, 0.0f);
    motion[2 * (3 * 9 + 4)] = std::nanf("");
    motion[2 * (5 * 9 + 2) + 1] = 1e30f;
    motion[2 * (1 * 9 + 1)] = -std::numeric_limits<float>::infinity();
    FeatureMap out;
    warpCatmullRom(previous, motion.data(), out);
    for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(out.pixel(3, 4)[c], previous.pixel(3, 4)[c]);
        EXPECT_EQ(out.pixel(5, 2)[c], previous.pixel(6, 2)[c]);
        EXPECT_EQ(out.pixel(1, 1)[c], previous.pixel(1, 0)[c]);
    }
}

TEST(WarpCatmullRom, RowsIntoARingEqualTheWholeImageOnAnyThreadCount) {
    std::mt19937 rng(53);
    const int height = 23, width = 19;
    const FeatureMap previous = randomMap(height, width, 3, -3.0f, 3.0f, rng);
    const std::vector<float> motion = randomMotion(height, width, 6.0f, rng);
    const int before = omp_get_max_threads();
    FeatureMap one, whole;
    omp_set_num_threads(1);
    warpCatmullRom(previous, motion.data(), one);
    omp_set_num_threads(2);
    warpCatmullRom(previous, motion.data(), whole);
    omp_set_num_threads(before);
    EXPECT_TRUE(bitwiseEqual(one, whole));
    FeatureMap ring(4, width, 3);
    for (int begin = 0; begin < height; begin += 4) {
        const int end = std::min(height, begin + 4);
        warpCatmullRomRows(previous, motion.data(), begin, end, ring);
        for (int y = begin; y < end; ++y)
            ASSERT_EQ(std::memcmp(ring.pixel(y % 4, 0), whole.pixel(y, 0), sizeof(float) * 3 * width), 0)
                << "row " << y;
    }
    FeatureMap tooShort(3, width, 3);
    EXPECT_THROW(warpCatmullRomRows(previous, motion.data(), 0, 4, tooShort), Error);
    EXPECT_THROW(warpCatmullRom(previous, nullptr, whole), Error);
}

}  // namespace
}  // namespace affinity
