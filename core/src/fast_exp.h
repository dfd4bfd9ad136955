#pragma once
// exp(x) for x <= 0 on eight float lanes: the affinity weights' exponential. A polynomial
// instead of std::exp so that it vectorises; max relative error about 2e-7 on [-87, 0]
// (tests/cpp/test_affinity_filter.cpp measures it). Below -87 the result is exactly 0:
// affinities that small are zero for every purpose here, and products of such tiny weights
// would be denormal numbers, which cost some processors a hundred cycles per operation.
#include <bit>
#include <cstdint>

#if defined(__AVX__)
#include <immintrin.h>
#endif

namespace affinity {

// GCC / clang vector extensions: plain arithmetic operators on eight lanes, compiled to AVX2
// with the project's -march, and to narrower or scalar code elsewhere.
using Vec8f = float __attribute__((vector_size(32)));
using Vec8i = std::int32_t __attribute__((vector_size(32)));

inline Vec8f broadcast8(float value) { return Vec8f{} + value; }

inline Vec8f fastExpNonPositive(Vec8f x) {
    // Cody-Waite: x = n ln2 + r with |r| <= ln2 / 2, exp(x) = 2^n exp(r).
    constexpr float kLog2e = 1.44269504088896341f;
    constexpr float kLn2High = 0.693145751953125f;  // few mantissa bits: n * kLn2High is exact
    constexpr float kLn2Low = 1.42860682030941723212e-6f;
    constexpr float kRoundMagic = 12582912.0f;  // 1.5 * 2^23: adding it rounds to an integer
    constexpr std::int32_t kRoundMagicBits = 0x4B400000;
    const Vec8f lowest = broadcast8(-87.0f);
    const Vec8i belowRange = x < lowest;  // off the dependency chain: applied at the end
#if defined(__AVX__)
    x = _mm256_max_ps(x, lowest);  // one instruction where the generic form needs two
#else
    x = belowRange ? lowest : x;
#endif
    const Vec8f shifted = x * kLog2e + kRoundMagic;
    const Vec8f n = shifted - kRoundMagic;
    // The integer n sits in the low mantissa bits of `shifted`.
    const Vec8i exponent = std::bit_cast<Vec8i>(shifted) - kRoundMagicBits;
    const Vec8f r = (x - n * kLn2High) - n * kLn2Low;
    // Taylor polynomial of degree 6 (truncation error below 1.2e-7 for |r| <= ln2 / 2),
    // evaluated in Estrin's scheme: a dependency chain of 4 operations instead of Horner's 7,
    // which matters because the filter's loop is bound by this chain's latency.
    const Vec8f r2 = r * r;
    const Vec8f low = r + 1.0f;
    const Vec8f middle = r * (1.0f / 6.0f) + 0.5f;
    const Vec8f high = (r2 * (1.0f / 720.0f) + (r * (1.0f / 120.0f) + 1.0f / 24.0f));
    const Vec8f p = r2 * (r2 * high + middle) + low;
    const Vec8i scaleBits = (exponent + 127) << 23;
    return belowRange ? Vec8f{} : p * std::bit_cast<Vec8f>(scaleBits);
}

// 1 / (1 + exp(-x)) on eight lanes, through exp(-|x|) so that the exponential's argument is
// never positive: for x < 0 it is exp(x) / (1 + exp(x)). Relative error about 3e-7.
inline Vec8f fastSigmoid(Vec8f x) {
    const Vec8f negativeMagnitude = std::bit_cast<Vec8f>(std::bit_cast<Vec8i>(x) | (Vec8i{} + INT32_MIN));  // -|x|
    const Vec8f e = fastExpNonPositive(negativeMagnitude);
    const Vec8f r = 1.0f / (1.0f + e);
    return x >= 0.0f ? r : e * r;
}

}  // namespace affinity
