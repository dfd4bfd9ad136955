// The bfloat16 products (core/src/kernels/bf16_gemm.h) against sums in double: over the operands rounded
// to bfloat16 they must agree to FP32 accumulation rounding; over the FP32 operands, to the
// 2^-7 relative rounding of two bfloat16 factors (8 significant bits: at most 2^-8 each).
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "affinity/error.h"
#include "kernels/bf16_gemm.h"

namespace affinity {
namespace {

float fromBFloat16(std::uint16_t h) {
    const std::uint32_t bits = std::uint32_t(h) << 16;
    float x;
    std::memcpy(&x, &bits, sizeof x);
    return x;
}

TEST(BFloat16, RoundsToNearestWithTiesToEven) {
    EXPECT_EQ(toBFloat16(1.0f), 0x3F80);
    EXPECT_EQ(toBFloat16(-2.0f), 0xC000);
    // 1 + 2^-8 lies halfway between 1 and 1 + 2^-7: ties go to the even mantissa (1).
    EXPECT_EQ(toBFloat16(1.0f + std::ldexp(1.0f, -8)), 0x3F80);
    // 1 + 3 * 2^-8 lies halfway between 1 + 2^-7 and 1 + 2^-6: ties go to 1 + 2^-6.
    EXPECT_EQ(toBFloat16(1.0f + 3 * std::ldexp(1.0f, -8)), 0x3F82);
    EXPECT_EQ(toBFloat16(1.0f + std::ldexp(1.0f, -8) + std::ldexp(1.0f, -12)), 0x3F81);
}

struct Shape {
    int rows, out, in;
    bool leaky;  // with a bias and the leaky ReLU
};

class Bf16GemmTest : public ::testing::TestWithParam<Shape> {};

TEST_P(Bf16GemmTest, MatchesDoubleSumsOfTheRoundedOperands) {
    if (!cpuHasAvx512Bf16()) GTEST_SKIP() << "no AVX512-BF16 on this CPU";
    const auto [rows, out, in, leaky] = GetParam();
    std::mt19937 rng(7);
    std::normal_distribution<float> normal;
    std::vector<float> w(std::size_t(out) * in), x(std::size_t(rows) * in), bias(std::size_t(out), 0.0f);
    for (float& v : w) v = normal(rng);
    if (leaky)
        for (float& v : bias) v = normal(rng);
    for (float& v : x) v = normal(rng) * 3.0f;
    const std::size_t xStride = std::size_t(in) + 2, outStride = std::size_t(out) + 3;  // padded rows
    std::vector<std::uint16_t> xb(std::size_t(rows) * xStride, 0);
    for (int r = 0; r < rows; ++r)
        convertToBf16(x.data() + std::size_t(r) * in, std::size_t(in), xb.data() + r * xStride);
    const PackedGemmBf16 packed(w.data(), out, in, leaky ? bias.data() : nullptr);
    const float sentinel = 12345.0f;
    std::vector<float> result(std::size_t(rows) * outStride, sentinel);
    gemmBf16(packed, xb.data(), xStride, rows, result.data(), outStride, leaky);
    auto act = [&](double v) { return leaky && v < 0 ? 0.01 * v : v; };
    for (int r = 0; r < rows; ++r) {
        for (int o = 0; o < out; ++o) {
            double rounded = bias[o], exact = bias[o], magnitude = std::abs(bias[o]);
            for (int c = 0; c < in; ++c) {
                const double a = x[std::size_t(r) * in + c], b = w[std::size_t(o) * in + c];
                rounded += double(fromBFloat16(xb[r * xStride + c])) * double(fromBFloat16(toBFloat16(float(b))));
                exact += a * b;
                magnitude += std::abs(a * b);
            }
            const double got = result[r * outStride + o];
            ASSERT_NEAR(got, act(rounded), 1e-6 * magnitude) << "row " << r << " channel " << o;
            ASSERT_NEAR(got, act(exact), std::ldexp(1.0, -7) * magnitude) << "row " << r << " channel " << o;
        }
        for (std::size_t o = std::size_t(out); o < outStride; ++o)
            ASSERT_EQ(result[r * outStride + o], sentinel) << "wrote past the row's channels";
    }
}

// 12-row blocks and their remainders, one and two vectors, half-width last vectors (<= 8 lanes),
// with and without bias and activation.
INSTANTIATE_TEST_SUITE_P(Shapes, Bf16GemmTest,
                         ::testing::Values(Shape{12, 24, 64, false}, Shape{12, 32, 32, true}, Shape{7, 16, 18, true},
                                           Shape{25, 8, 2, false}, Shape{13, 40, 56, true}, Shape{1, 5, 6, true},
                                           Shape{36, 48, 24, false}, Shape{24, 24, 18, true}));

TEST(Bf16Gemm, RefusesAnOddInputChannelCount) {
    const std::vector<float> w(3 * 5, 1.0f);
    if (!cpuHasAvx512Bf16()) {
        EXPECT_THROW(PackedGemmBf16(w.data(), 3, 4), Error);
        return;
    }
    try {
        PackedGemmBf16(w.data(), 3, 5);
        FAIL() << "an odd input channel count was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("even"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace affinity
