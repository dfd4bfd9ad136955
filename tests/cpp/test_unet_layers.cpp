// The U-Net layers against naive double-precision references (docs/MODEL.md section 4):
// convolutions over many shapes and channel counts, the two-input (skip connection) form,
// the coarser level read upsampled, row by row, pooling and upsampling on odd sizes, and
// independence from the thread count.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "affinity/error.h"
#include "network/unet_layers.h"

namespace affinity {
namespace {

std::vector<float> randomValues(std::size_t count, std::mt19937& rng, float scale = 1.0f) {
    std::uniform_real_distribution<float> dist(-scale, scale);
    std::vector<float> values(count);
    for (float& v : values) v = dist(rng);
    return values;
}

FeatureMap randomMap(int height, int width, int channels, std::mt19937& rng) {
    FeatureMap map(height, width, channels);
    const std::vector<float> values = randomValues(map.size(), rng);
    std::copy(values.begin(), values.end(), map.data());
    return map;
}

struct ConvWeights {
    int out, in, size;
    std::vector<float> weight, bias;
};

ConvWeights randomConv(int out, int in, int size, std::mt19937& rng) {
    // Scaled like a trained layer so activations stay O(1).
    const float scale = 1.0f / std::sqrt(float(in * size * size));
    return {out, in, size, randomValues(std::size_t(out) * in * size * size, rng, scale),
            randomValues(std::size_t(out), rng)};
}

// Reference: double accumulation over the zero-padded input; also returns the sum of
// |terms| per output, which bounds the float rounding error.
void referenceConv(const ConvWeights& w, const FeatureMap& input, Activation activation, std::vector<double>& out,
                   std::vector<double>& magnitude) {
    const int h = input.height(), wd = input.width(), r = w.size / 2;
    out.assign(std::size_t(h) * wd * w.out, 0.0);
    magnitude.assign(out.size(), 0.0);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < wd; ++x)
            for (int o = 0; o < w.out; ++o) {
                double sum = w.bias[o], mag = std::abs(w.bias[o]);
                for (int ky = 0; ky < w.size; ++ky)
                    for (int kx = 0; kx < w.size; ++kx) {
                        const int sy = y + ky - r, sx = x + kx - r;
                        if (sy < 0 || sy >= h || sx < 0 || sx >= wd) continue;
                        for (int c = 0; c < w.in; ++c) {
                            const double term = double(input.pixel(sy, sx)[c]) *
                                                w.weight[((std::size_t(o) * w.in + c) * w.size + ky) * w.size + kx];
                            sum += term;
                            mag += std::abs(term);
                        }
                    }
                if (activation == Activation::LeakyRelu && sum < 0) sum *= 0.01;
                const std::size_t i = (std::size_t(y) * wd + x) * w.out + o;
                out[i] = sum;
                magnitude[i] = mag;
            }
}

FeatureMap concat(const FeatureMap& a, const FeatureMap& b) {
    FeatureMap result(a.height(), a.width(), a.channels() + b.channels());
    for (int y = 0; y < a.height(); ++y)
        for (int x = 0; x < a.width(); ++x) {
            std::copy(a.pixel(y, x), a.pixel(y, x) + a.channels(), result.pixel(y, x));
            std::copy(b.pixel(y, x), b.pixel(y, x) + b.channels(), result.pixel(y, x) + a.channels());
        }
    return result;
}

bool bitwiseEqual(const FeatureMap& a, const FeatureMap& b) {
    return a.height() == b.height() && a.width() == b.width() && a.channels() == b.channels() &&
           std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

// Checks conv against the reference; returns the number of mismatching values.
int countMismatches(const FeatureMap& output, const ConvWeights& w, const FeatureMap& input, Activation activation);

int checkConv(const ConvWeights& w, const FeatureMap& input, Activation activation) {
    const Conv2d conv(w.weight.data(), w.bias.data(), w.out, w.in, w.size);
    FeatureMap output;
    conv.apply(input, activation, output);
    return countMismatches(output, w, input, activation);
}

// The values of `output` that differ from the reference convolution of `input` by more than
// float rounding allows.
int countMismatches(const FeatureMap& output, const ConvWeights& w, const FeatureMap& input, Activation activation) {
    EXPECT_EQ(output.height(), input.height());
    EXPECT_EQ(output.width(), input.width());
    EXPECT_EQ(output.channels(), w.out);
    std::vector<double> expected, magnitude;
    referenceConv(w, input, activation, expected, magnitude);
    int bad = 0;
    for (std::size_t i = 0; i < expected.size(); ++i) {
        // Float accumulation of n terms: error well below 1e-5 of the sum of magnitudes
        // (a single missing or wrong term would be about 1/n of it).
        const double tolerance = 1e-5 * magnitude[i] + 1e-7;
        if (!(std::abs(output.data()[i] - expected[i]) <= tolerance)) {
            if (bad < 3) ADD_FAILURE() << "value " << i << ": got " << output.data()[i] << ", expected " << expected[i];
            ++bad;
        }
    }
    return bad;
}

struct Size {
    int height, width;
};
const Size kSizes[] = {{1, 1}, {1, 7}, {7, 1}, {7, 13}, {33, 17}, {2, 2}};
const int kChannels[] = {1, 3, 5, 8, 13, 16, 32, 35};

TEST(Conv2d, MatchesReferenceAllShapes3x3) {
    std::mt19937 rng(1);
    for (const Size size : kSizes)
        for (const int in : kChannels)
            for (const int out : kChannels) {
                SCOPED_TRACE(std::to_string(size.height) + "x" + std::to_string(size.width) + " in " +
                             std::to_string(in) + " out " + std::to_string(out));
                const FeatureMap input = randomMap(size.height, size.width, in, rng);
                const ConvWeights w = randomConv(out, in, 3, rng);
                ASSERT_EQ(checkConv(w, input, Activation::LeakyRelu), 0);
                ASSERT_EQ(checkConv(w, input, Activation::None), 0);
            }
}

TEST(Conv2d, MatchesReferenceAllShapes1x1) {
    std::mt19937 rng(2);
    for (const Size size : kSizes)
        for (const int in : kChannels)
            for (const int out : kChannels) {
                SCOPED_TRACE(std::to_string(size.height) + "x" + std::to_string(size.width) + " in " +
                             std::to_string(in) + " out " + std::to_string(out));
                const FeatureMap input = randomMap(size.height, size.width, in, rng);
                const ConvWeights w = randomConv(out, in, 1, rng);
                ASSERT_EQ(checkConv(w, input, Activation::LeakyRelu), 0);
                ASSERT_EQ(checkConv(w, input, Activation::None), 0);
            }
}

TEST(Conv2d, WideRowsCrossTiles) {
    // Wider than the kernel's column tiles, with a ragged last tile.
    std::mt19937 rng(3);
    const FeatureMap input = randomMap(5, 301, 24, rng);
    EXPECT_EQ(checkConv(randomConv(32, 24, 3, rng), input, Activation::LeakyRelu), 0);
    EXPECT_EQ(checkConv(randomConv(7, 24, 3, rng), input, Activation::None), 0);
    EXPECT_EQ(checkConv(randomConv(64, 24, 1, rng), input, Activation::None), 0);
}

TEST(Conv2d, LeakyReluIsMaxOfXAndScaledX) {
    // A 1x1 identity layer shows the activation alone.
    const float weight = 1.0f, bias = 0.0f;
    const Conv2d conv(&weight, &bias, 1, 1, 1);
    FeatureMap input(1, 4, 1), output;
    const float values[4] = {-2.0f, -0.0f, 0.5f, 3.0f};
    std::copy(values, values + 4, input.data());
    conv.apply(input, Activation::LeakyRelu, output);
    EXPECT_FLOAT_EQ(output.data()[0], -0.02f);
    EXPECT_EQ(output.data()[1], 0.0f);
    EXPECT_EQ(output.data()[2], 0.5f);
    EXPECT_EQ(output.data()[3], 3.0f);
}

TEST(Conv2d, TwoInputsEqualExplicitConcat) {
    std::mt19937 rng(4);
    const int splits[][2] = {{1, 1}, {3, 5}, {16, 16}, {32, 32}, {13, 35}, {8, 1}, {35, 13}};
    for (const Size size : kSizes)
        for (const auto& split : splits)
            for (const int out : {5, 16, 32})
                for (const int kernel : {1, 3}) {
                    SCOPED_TRACE(std::to_string(size.height) + "x" + std::to_string(size.width) + " split " +
                                 std::to_string(split[0]) + "+" + std::to_string(split[1]) + " out " +
                                 std::to_string(out) + " size " + std::to_string(kernel));
                    const FeatureMap first = randomMap(size.height, size.width, split[0], rng);
                    const FeatureMap second = randomMap(size.height, size.width, split[1], rng);
                    const ConvWeights w = randomConv(out, split[0] + split[1], kernel, rng);
                    const Conv2d conv(w.weight.data(), w.bias.data(), w.out, w.in, w.size);
                    FeatureMap viaTwo, viaConcat;
                    conv.apply(first, second, Activation::LeakyRelu, viaTwo);
                    conv.apply(concat(first, second), Activation::LeakyRelu, viaConcat);
                    ASSERT_TRUE(bitwiseEqual(viaTwo, viaConcat));
                    ASSERT_EQ(checkConv(w, concat(first, second), Activation::LeakyRelu), 0);
                }
}

TEST(Conv2d, UpsampledInputEqualsExplicitUpsampling) {
    std::mt19937 rng(13);
    const int splits[][2] = {{1, 1}, {3, 5}, {32, 24}, {13, 35}};
    for (const Size size : kSizes)
        for (const auto& split : splits)
            for (const int out : {5, 24})
                for (const int kernel : {1, 3}) {
                    SCOPED_TRACE(std::to_string(size.height) + "x" + std::to_string(size.width) + " split " +
                                 std::to_string(split[0]) + "+" + std::to_string(split[1]) + " out " +
                                 std::to_string(out) + " size " + std::to_string(kernel));
                    const FeatureMap coarse = randomMap((size.height + 1) / 2, (size.width + 1) / 2, split[0], rng);
                    const FeatureMap skip = randomMap(size.height, size.width, split[1], rng);
                    const ConvWeights w = randomConv(out, split[0] + split[1], kernel, rng);
                    const Conv2d conv(w.weight.data(), w.bias.data(), w.out, w.in, w.size);
                    FeatureMap upsampled, fused, explicitly;
                    upsampleNearest(coarse, size.height, size.width, upsampled);
                    conv.applyUpsampled(coarse, skip, Activation::LeakyRelu, fused);
                    conv.apply(upsampled, skip, Activation::LeakyRelu, explicitly);
                    ASSERT_TRUE(bitwiseEqual(fused, explicitly));
                }
}

TEST(Conv2d, InstructionSetsAgreeBitwise) {
    // The reference tests above run the default (widest) kernel; this holds the AVX2 kernel to
    // the AVX-512 one bit for bit: both accumulate each output in the same order. Channel
    // counts straddle the 8- and 16-lane blocks (24 = 16 + 8 at half width, 33 = 32 + 1); the
    // folded form's 20 coarse channels run its transforms as 16 + 4 lanes against 8 + 8 + 4.
    if (!cpuHasAvx512()) GTEST_SKIP() << "this CPU has no AVX-512: only the AVX2 kernel runs here";
    std::mt19937 rng(21);
    for (const Size size : {Size{7, 13}, Size{33, 17}, Size{3, 40}})
        for (const int out : {1, 5, 8, 9, 16, 17, 24, 25, 32, 33, 48, 64})
            for (const int kernel : {1, 3}) {
                SCOPED_TRACE(std::to_string(size.height) + "x" + std::to_string(size.width) + " out " +
                             std::to_string(out) + " size " + std::to_string(kernel));
                const FeatureMap coarse = randomMap((size.height + 1) / 2, (size.width + 1) / 2, 20, rng);
                const FeatureMap skip = randomMap(size.height, size.width, 19, rng);
                const ConvWeights one = randomConv(out, 19, kernel, rng);
                const ConvWeights two = randomConv(out, 39, kernel, rng);
                FeatureMap narrow, wide;
                Conv2d(one.weight.data(), one.bias.data(), out, 19, kernel, ConvIsa::Avx2)
                    .apply(skip, Activation::LeakyRelu, narrow);
                Conv2d(one.weight.data(), one.bias.data(), out, 19, kernel, ConvIsa::Avx512)
                    .apply(skip, Activation::LeakyRelu, wide);
                ASSERT_TRUE(bitwiseEqual(narrow, wide));
                for (const int upsampledChannels : {0, kernel == 3 ? 20 : 0}) {
                    Conv2d(two.weight.data(), two.bias.data(), out, 39, kernel, ConvIsa::Avx2, upsampledChannels)
                        .applyUpsampled(coarse, skip, Activation::None, narrow);
                    Conv2d(two.weight.data(), two.bias.data(), out, 39, kernel, ConvIsa::Avx512, upsampledChannels)
                        .applyUpsampled(coarse, skip, Activation::None, wide);
                    ASSERT_TRUE(bitwiseEqual(narrow, wide));
                }
            }
}

TEST(Conv2d, DefaultInstructionSetIsTheWidestAvailable) {
    const float weight = 1.0f;
    const Conv2d conv(&weight, nullptr, 1, 1, 1);
    // AFFINITY_CONV_ISA=avx2 is the one way to ask for less (benchmarks compare the two).
    const char* forced = std::getenv("AFFINITY_CONV_ISA");
    const bool avx2Asked = forced && std::string(forced) == "avx2";
    EXPECT_EQ(defaultConvIsa(), cpuHasAvx512() && !avx2Asked ? ConvIsa::Avx512 : ConvIsa::Avx2);
    if (!cpuHasAvx512()) {
        EXPECT_THROW(Conv2d(&weight, nullptr, 1, 1, 1, ConvIsa::Avx512), Error);
    }
}

TEST(Conv2d, FoldedUpsampledInputMatchesReference) {
    // A decoder layer (built with upsampledChannels) folds the coarse level's 3x3 taps into 2x2
    // per row and column parity: against the double-precision reference on the explicit
    // upsampled concatenation, on even and odd sizes (odd last rows and columns are unfolded).
    std::mt19937 rng(22);
    const Size sizes[] = {{1, 1}, {1, 7}, {7, 1}, {2, 2}, {7, 13}, {8, 10}, {9, 12}, {12, 9}, {33, 17}, {4, 40}};
    const int splits[][2] = {{1, 1}, {3, 5}, {32, 24}, {13, 35}};
    for (const Size size : sizes)
        for (const auto& split : splits)
            for (const int out : {5, 24, 33}) {
                SCOPED_TRACE(std::to_string(size.height) + "x" + std::to_string(size.width) + " split " +
                             std::to_string(split[0]) + "+" + std::to_string(split[1]) + " out " + std::to_string(out));
                const FeatureMap coarse = randomMap((size.height + 1) / 2, (size.width + 1) / 2, split[0], rng);
                const FeatureMap skip = randomMap(size.height, size.width, split[1], rng);
                const ConvWeights w = randomConv(out, split[0] + split[1], 3, rng);
                const Conv2d folded(w.weight.data(), w.bias.data(), w.out, w.in, 3, defaultConvIsa(), split[0]);
                FeatureMap upsampled, output;
                upsampleNearest(coarse, size.height, size.width, upsampled);
                const FeatureMap explicitInput = concat(upsampled, skip);
                folded.applyUpsampled(coarse, skip, Activation::LeakyRelu, output);
                ASSERT_EQ(countMismatches(output, w, explicitInput, Activation::LeakyRelu), 0);
                folded.applyUpsampled(coarse, skip, Activation::None, output);
                ASSERT_EQ(countMismatches(output, w, explicitInput, Activation::None), 0);
            }
}

TEST(Conv2d, FoldedFormRejectsAnUnfoldableLayer) {
    std::mt19937 rng(23);
    const ConvWeights w = randomConv(4, 6, 3, rng), point = randomConv(4, 6, 1, rng);
    EXPECT_THROW(Conv2d(w.weight.data(), w.bias.data(), 4, 6, 3, defaultConvIsa(), 6), Error);
    EXPECT_THROW(Conv2d(point.weight.data(), point.bias.data(), 4, 6, 1, defaultConvIsa(), 2), Error);
    // Inputs that are not (an upsampled coarse level of that width, a skip) take the ordinary path.
    const Conv2d folded(w.weight.data(), w.bias.data(), 4, 6, 3, defaultConvIsa(), 2);
    const FeatureMap input = randomMap(5, 7, 6, rng);
    FeatureMap output;
    folded.apply(input, Activation::None, output);
    EXPECT_EQ(countMismatches(output, w, input, Activation::None), 0);
}

void checkRowsEqualTheWholeImage(const Conv2d& conv, const ConvWeights& w, const FeatureMap& coarse,
                                 const FeatureMap& skip);

TEST(Conv2d, RowsEqualTheWholeImage) {
    std::mt19937 rng(14);
    const FeatureMap coarse = randomMap(16, 66, 7, rng);
    const FeatureMap skip = randomMap(31, 131, 5, rng);
    const ConvWeights w = randomConv(19, 12, 3, rng);
    // Unfolded, folded (its skip part in the Winograd form) and Winograd: the
    // folded form splits column parities at the odd range starts.
    for (const auto& [upsampledChannels, form] :
         {std::pair{0, ConvForm::Direct}, std::pair{7, ConvForm::Direct}, std::pair{0, ConvForm::Winograd}}) {
        SCOPED_TRACE("upsampled channels " + std::to_string(upsampledChannels) +
                     (form == ConvForm::Winograd ? ", Winograd" : ""));
        checkRowsEqualTheWholeImage(
            Conv2d(w.weight.data(), w.bias.data(), w.out, w.in, w.size, defaultConvIsa(), upsampledChannels, form), w,
            coarse, skip);
    }
}

// Row groups give the whole image's values bit for bit; single rows (always the direct form) the
// same function within the reference's tolerance.
void checkRowsEqualTheWholeImage(const Conv2d& conv, const ConvWeights& w, const FeatureMap& coarse,
                                 const FeatureMap& skip) {
    FeatureMap whole;
    conv.applyUpsampled(coarse, skip, Activation::LeakyRelu, whole);
    const ConvSource sources[2] = {{coarse.data(), coarse.channels(), true}, {skip.data(), skip.channels()}};
    FeatureMap groups(31, 131, 19), rows(31, 131, 19);
    groups.fill(-1.0f);
    rows.fill(-1.0f);
    // Ragged column ranges (odd starts included), each row filled piece by piece.
    for (const auto& range : {std::pair{0, 3}, std::pair{3, 70}, std::pair{70, 131}}) {
        for (int y = 0; y < 31; y += kWinogradRows) {
            float* group[kWinogradRows];
            for (int r = 0; r < kWinogradRows; ++r) group[r] = y + r < 31 ? groups.pixel(y + r, 0) : nullptr;
            conv.applyRowGroup(sources, 2, 31, 131, y, range.first, range.second, Activation::LeakyRelu, group);
        }
        for (int y = 0; y < 31; ++y)
            conv.applyRow(sources, 2, 31, 131, y, range.first, range.second, Activation::LeakyRelu, rows.pixel(y, 0));
    }
    EXPECT_TRUE(bitwiseEqual(groups, whole));
    FeatureMap upsampled;
    upsampleNearest(coarse, 31, 131, upsampled);
    EXPECT_EQ(countMismatches(rows, w, concat(upsampled, skip), Activation::LeakyRelu), 0);
    float out[kWinogradRows][131 * 19];
    EXPECT_THROW(conv.applyRow(sources, 1, 31, 131, 0, 0, 131, Activation::None, out[0]), Error);
    EXPECT_THROW(conv.applyRow(sources, 2, 31, 131, 31, 0, 131, Activation::None, out[0]), Error);
    EXPECT_THROW(conv.applyRow(sources, 2, 31, 131, 0, 0, 132, Activation::None, out[0]), Error);
    static_assert(kWinogradRows == 4, "the groups below are written out for 4 rows");
    float* const full[kWinogradRows] = {out[0], out[1], out[2], out[3]};
    float* const lastRowsOnly[kWinogradRows] = {out[0], out[1], out[2], nullptr};  // rows 28-30 of 31
    EXPECT_THROW(conv.applyRowGroup(sources, 2, 31, 131, 2, 0, 131, Activation::None, full), Error);
    EXPECT_THROW(conv.applyRowGroup(sources, 2, 31, 131, 28, 0, 131, Activation::None, full), Error);
    EXPECT_THROW(conv.applyRowGroup(sources, 2, 31, 131, 0, 0, 131, Activation::None, lastRowsOnly), Error);
    EXPECT_NO_THROW(conv.applyRowGroup(sources, 2, 31, 131, 28, 0, 131, Activation::None, lastRowsOnly));
}

TEST(Conv2d, RejectsAnUpsampledInputOfTheWrongSize) {
    std::mt19937 rng(15);
    const ConvWeights w = randomConv(4, 6, 3, rng);
    const Conv2d conv(w.weight.data(), w.bias.data(), 4, 6, 3);
    FeatureMap output;
    EXPECT_THROW(conv.applyUpsampled(randomMap(4, 4, 3, rng), randomMap(7, 9, 3, rng), Activation::None, output),
                 Error);
    EXPECT_THROW(conv.applyUpsampled(randomMap(4, 5, 2, rng), randomMap(7, 9, 3, rng), Activation::None, output),
                 Error);
    EXPECT_NO_THROW(conv.applyUpsampled(randomMap(4, 5, 3, rng), randomMap(7, 9, 3, rng), Activation::None, output));
}

TEST(Conv2d, ThreadCountDoesNotChangeResults) {
    std::mt19937 rng(5);
    const int shapes[][3] = {{32, 32, 3}, {13, 35, 3}, {64, 64, 3}, {5, 32, 1}, {35, 13, 1}};
    const int saved = omp_get_max_threads();
    for (const auto& shape : shapes) {
        SCOPED_TRACE("in " + std::to_string(shape[0]) + " out " + std::to_string(shape[1]));
        // Large enough for the layer to run in parallel, ragged in both directions.
        const FeatureMap input = randomMap(61, 263, shape[0], rng);
        const FeatureMap skip = randomMap(61, 263, 3, rng);
        const ConvWeights w = randomConv(shape[1], shape[0], shape[2], rng);
        const ConvWeights w2 = randomConv(shape[1], shape[0] + 3, shape[2], rng);
        const Conv2d conv(w.weight.data(), w.bias.data(), w.out, w.in, w.size);
        const Conv2d conv2(w2.weight.data(), w2.bias.data(), w2.out, w2.in, w2.size, defaultConvIsa(),
                           shape[2] == 3 ? shape[0] : 0);  // the 3x3 ones fold the upsampled input
        const FeatureMap coarse = randomMap(31, 132, shape[0], rng);
        FeatureMap one, two, oneSkip, twoSkip, oneUp, twoUp;
        omp_set_num_threads(1);
        conv.apply(input, Activation::LeakyRelu, one);
        conv2.apply(input, skip, Activation::LeakyRelu, oneSkip);
        conv2.applyUpsampled(coarse, skip, Activation::LeakyRelu, oneUp);
        omp_set_num_threads(2);
        conv.apply(input, Activation::LeakyRelu, two);
        conv2.apply(input, skip, Activation::LeakyRelu, twoSkip);
        conv2.applyUpsampled(coarse, skip, Activation::LeakyRelu, twoUp);
        EXPECT_TRUE(bitwiseEqual(one, two));
        EXPECT_TRUE(bitwiseEqual(oneSkip, twoSkip));
        EXPECT_TRUE(bitwiseEqual(oneUp, twoUp));
    }
    omp_set_num_threads(saved);
}

TEST(Conv2d, RejectsBadShapes) {
    std::mt19937 rng(6);
    const ConvWeights w = randomConv(4, 6, 3, rng);
    EXPECT_THROW(Conv2d(w.weight.data(), w.bias.data(), 4, 6, 2), Error);
    EXPECT_THROW(Conv2d(w.weight.data(), w.bias.data(), 0, 6, 3), Error);
    const Conv2d conv(w.weight.data(), w.bias.data(), 4, 6, 3);
    FeatureMap output;
    EXPECT_THROW(conv.apply(randomMap(3, 3, 5, rng), Activation::None, output), Error);
    EXPECT_THROW(conv.apply(randomMap(3, 3, 3, rng), randomMap(3, 3, 2, rng), Activation::None, output), Error);
    EXPECT_THROW(conv.apply(randomMap(3, 3, 3, rng), randomMap(3, 4, 3, rng), Activation::None, output), Error);
    FeatureMap same = randomMap(3, 3, 6, rng);
    EXPECT_THROW(conv.apply(same, Activation::None, same), Error);
}

TEST(Conv2d, ReusesOutputOfAnotherShape) {
    std::mt19937 rng(7);
    const ConvWeights w = randomConv(13, 5, 3, rng);
    FeatureMap output(40, 40, 3);
    output.fill(1e30f);
    const Conv2d conv(w.weight.data(), w.bias.data(), w.out, w.in, w.size);
    const FeatureMap input = randomMap(9, 11, 5, rng);
    FeatureMap fresh;
    conv.apply(input, Activation::None, output);
    conv.apply(input, Activation::None, fresh);
    EXPECT_TRUE(bitwiseEqual(output, fresh));
}

// The Winograd form (winograd_conv.h) against the same double-precision reference and
// tolerance as the direct form: odd and even sizes (tiles past the last row and column), one
// and two inputs, an upsampled input read unfolded, wider than a unit of work (96 columns).
Conv2d winogradConv(const ConvWeights& w, ConvIsa isa = defaultConvIsa()) {
    return Conv2d(w.weight.data(), w.bias.data(), w.out, w.in, 3, isa, 0, ConvForm::Winograd);
}

TEST(Conv2dWinograd, MatchesReferenceAllShapes) {
    std::mt19937 rng(31);
    const Size sizes[] = {{1, 1}, {1, 7}, {7, 1}, {2, 2}, {7, 13}, {8, 10}, {33, 17}, {5, 301}};
    for (const Size size : sizes)
        for (const int in : {1, 3, 8, 13, 24, 35, 64})
            for (const int out : {1, 5, 16, 24, 33}) {
                SCOPED_TRACE(std::to_string(size.height) + "x" + std::to_string(size.width) + " in " +
                             std::to_string(in) + " out " + std::to_string(out));
                const FeatureMap input = randomMap(size.height, size.width, in, rng);
                const ConvWeights w = randomConv(out, in, 3, rng);
                const Conv2d conv = winogradConv(w);
                for (const Activation activation : {Activation::LeakyRelu, Activation::None}) {
                    FeatureMap output;
                    conv.apply(input, activation, output);
                    ASSERT_EQ(countMismatches(output, w, input, activation), 0);
                }
            }
}

TEST(Conv2dWinograd, TwoAndUpsampledInputsEqualExplicitOnes) {
    std::mt19937 rng(32);
    for (const Size size : {Size{7, 13}, Size{8, 10}, Size{1, 1}, Size{33, 17}})
        for (const int out : {5, 24}) {
            SCOPED_TRACE(std::to_string(size.height) + "x" + std::to_string(size.width) + " out " +
                         std::to_string(out));
            const FeatureMap first = randomMap(size.height, size.width, 13, rng);
            const FeatureMap second = randomMap(size.height, size.width, 32, rng);
            const FeatureMap coarse = randomMap((size.height + 1) / 2, (size.width + 1) / 2, 13, rng);
            const ConvWeights w = randomConv(out, 45, 3, rng);
            const Conv2d conv = winogradConv(w);
            FeatureMap viaTwo, viaConcat, viaCoarse, upsampled, viaUpsampled;
            conv.apply(first, second, Activation::LeakyRelu, viaTwo);
            conv.apply(concat(first, second), Activation::LeakyRelu, viaConcat);
            ASSERT_TRUE(bitwiseEqual(viaTwo, viaConcat));
            ASSERT_EQ(countMismatches(viaTwo, w, concat(first, second), Activation::LeakyRelu), 0);
            upsampleNearest(coarse, size.height, size.width, upsampled);
            conv.applyUpsampled(coarse, second, Activation::LeakyRelu, viaCoarse);
            conv.apply(upsampled, second, Activation::LeakyRelu, viaUpsampled);
            ASSERT_TRUE(bitwiseEqual(viaCoarse, viaUpsampled));
        }
}

TEST(Conv2dWinograd, ThreadCountAndInstructionSetChangeNoBit) {
    std::mt19937 rng(33);
    const int saved = omp_get_max_threads();
    for (const auto& shape : {std::pair{64, 24}, std::pair{24, 32}, std::pair{13, 35}}) {
        SCOPED_TRACE("in " + std::to_string(shape.first) + " out " + std::to_string(shape.second));
        // Large enough to run in parallel; odd in both directions.
        const FeatureMap input = randomMap(61, 263, shape.first, rng);
        const ConvWeights w = randomConv(shape.second, shape.first, 3, rng);
        const Conv2d conv = winogradConv(w);
        FeatureMap one, two;
        omp_set_num_threads(1);
        conv.apply(input, Activation::LeakyRelu, one);
        omp_set_num_threads(2);
        conv.apply(input, Activation::LeakyRelu, two);
        EXPECT_TRUE(bitwiseEqual(one, two));
        EXPECT_EQ(countMismatches(two, w, input, Activation::LeakyRelu), 0);
        if (cpuHasAvx512()) {
            FeatureMap narrow, wide;
            winogradConv(w, ConvIsa::Avx2).apply(input, Activation::LeakyRelu, narrow);
            winogradConv(w, ConvIsa::Avx512).apply(input, Activation::LeakyRelu, wide);
            EXPECT_TRUE(bitwiseEqual(narrow, wide));
        }
    }
    omp_set_num_threads(saved);
}

TEST(Conv2dWinograd, RejectsLayersItCannotRun) {
    std::mt19937 rng(34);
    const ConvWeights point = randomConv(4, 6, 1, rng), w = randomConv(4, 6, 3, rng);
    EXPECT_THROW(Conv2d(point.weight.data(), point.bias.data(), 4, 6, 1, defaultConvIsa(), 0, ConvForm::Winograd),
                 Error);
    EXPECT_THROW(Conv2d(w.weight.data(), w.bias.data(), 4, 6, 3, defaultConvIsa(), 2, ConvForm::Winograd), Error);
}

TEST(MaxPool2x2, CeilModeOnOddSizes) {
    std::mt19937 rng(8);
    const Size sizes[] = {{1, 1}, {1, 7}, {7, 1}, {7, 13}, {33, 17}, {2, 2}, {4, 6}, {3, 300}};
    for (const Size size : sizes)
        for (const int channels : {1, 3, 13, 32, 35}) {
            SCOPED_TRACE(std::to_string(size.height) + "x" + std::to_string(size.width) + "x" +
                         std::to_string(channels));
            const FeatureMap input = randomMap(size.height, size.width, channels, rng);
            FeatureMap output;
            maxPool2x2(input, output);
            ASSERT_EQ(output.height(), (size.height + 1) / 2);
            ASSERT_EQ(output.width(), (size.width + 1) / 2);
            ASSERT_EQ(output.channels(), channels);
            for (int y = 0; y < output.height(); ++y)
                for (int x = 0; x < output.width(); ++x)
                    for (int c = 0; c < channels; ++c) {
                        float expected = -INFINITY;
                        for (int dy = 0; dy < 2; ++dy)
                            for (int dx = 0; dx < 2; ++dx)
                                if (2 * y + dy < size.height && 2 * x + dx < size.width)
                                    expected = std::max(expected, input.pixel(2 * y + dy, 2 * x + dx)[c]);
                        ASSERT_EQ(output.pixel(y, x)[c], expected) << y << " " << x << " " << c;
                    }
        }
}

TEST(MaxPool2x2, LargeMapIsThreadIndependent) {
    std::mt19937 rng(9);
    const FeatureMap input = randomMap(101, 257, 16, rng);
    const int saved = omp_get_max_threads();
    FeatureMap one, two;
    omp_set_num_threads(1);
    maxPool2x2(input, one);
    omp_set_num_threads(2);
    maxPool2x2(input, two);
    omp_set_num_threads(saved);
    EXPECT_TRUE(bitwiseEqual(one, two));
}

TEST(UpsampleNearest, ToOddSizes) {
    std::mt19937 rng(10);
    const Size sizes[] = {{1, 1}, {1, 7}, {7, 1}, {7, 13}, {33, 17}, {2, 2}, {4, 6}, {301, 5}};
    for (const Size size : sizes)
        for (const int channels : {1, 3, 32, 35}) {
            SCOPED_TRACE(std::to_string(size.height) + "x" + std::to_string(size.width) + "x" +
                         std::to_string(channels));
            const FeatureMap low = randomMap((size.height + 1) / 2, (size.width + 1) / 2, channels, rng);
            FeatureMap output;
            upsampleNearest(low, size.height, size.width, output);
            ASSERT_EQ(output.height(), size.height);
            ASSERT_EQ(output.width(), size.width);
            ASSERT_EQ(output.channels(), channels);
            for (int y = 0; y < size.height; ++y)
                for (int x = 0; x < size.width; ++x)
                    for (int c = 0; c < channels; ++c)
                        ASSERT_EQ(output.pixel(y, x)[c], low.pixel(y / 2, x / 2)[c]) << y << " " << x << " " << c;
        }
}

TEST(UpsampleNearest, PoolThenUpsampleRestoresSize) {
    std::mt19937 rng(11);
    const FeatureMap input = randomMap(33, 17, 8, rng);
    FeatureMap low, up;
    maxPool2x2(input, low);
    upsampleNearest(low, input.height(), input.width(), up);
    EXPECT_EQ(up.height(), 33);
    EXPECT_EQ(up.width(), 17);
}

TEST(UpsampleNearest, RejectsTooSmallInput) {
    std::mt19937 rng(12);
    FeatureMap output;
    EXPECT_THROW(upsampleNearest(randomMap(3, 4, 2, rng), 7, 7, output), Error);
    EXPECT_THROW(upsampleNearest(randomMap(4, 3, 2, rng), 7, 7, output), Error);
    EXPECT_NO_THROW(upsampleNearest(randomMap(4, 4, 2, rng), 7, 7, output));
}

}  // namespace
}  // namespace affinity
