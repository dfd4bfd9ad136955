#pragma once
// exp(x) for x <= 0 on 8 or 16 float lanes: the affinity weights' exponential. A polynomial
// instead of std::exp so that it vectorises; max relative error about 2e-7 on [-87, 0]
// (tests/cpp/test_affinity_filter.cpp measures it). Below -87 the result is exactly 0:
// affinities that small are zero for every purpose here, and products of such tiny weights
// would be denormal numbers, which cost some processors a hundred cycles per operation.
// Every lane goes through the same operations whatever the width, so 8- and 16-lane results
// agree bit for bit.
#include <bit>
#include <cstdint>

#if defined(__AVX__)
#include <immintrin.h>
#endif

namespace affinity {
// Internal linkage: the AVX-512 translation unit (affinity_filter_avx512.cpp) includes this
// too, and its copies must never be the ones the linker keeps for AVX2 code.
namespace {

// GCC / clang vector extensions: plain arithmetic operators on L lanes, compiled to AVX2 (or
// AVX-512 for 16 lanes in a translation unit built for it) and to narrower code elsewhere.
template <int L>
struct Lanes {
    typedef float F __attribute__((vector_size(4 * L)));
    typedef std::int32_t I __attribute__((vector_size(4 * L)));
};
template <int L>
using VecF = typename Lanes<L>::F;
template <int L>
using VecI = typename Lanes<L>::I;
using Vec8f = VecF<8>;
using Vec8i = VecI<8>;

inline Vec8f broadcast8(float value) { return Vec8f{} + value; }

// max(x, lowest), NaN giving `lowest` as maxps does: one instruction where the generic form
// needs two.
template <int L>
inline VecF<L> maxLowest(VecF<L> x, VecF<L> lowest, VecI<L> belowRange) {
#if defined(__AVX512F__)
    // maskz with every lane: GCC 12's plain _mm512_max_ps trips -Wuninitialized.
    if constexpr (L == 16) return _mm512_maskz_max_ps(__mmask16(0xFFFF), x, lowest);
#endif
#if defined(__AVX__)
    if constexpr (L == 8) return _mm256_max_ps(x, lowest);
#endif
    return belowRange ? lowest : x;
}

template <int L>
inline VecF<L> fastExpNonPositiveLanes(VecF<L> x) {
    // Cody-Waite: x = n ln2 + r with |r| <= ln2 / 2, exp(x) = 2^n exp(r).
    constexpr float kLog2e = 1.44269504088896341f;
    constexpr float kLn2High = 0.693145751953125f;  // few mantissa bits: n * kLn2High is exact
    constexpr float kLn2Low = 1.42860682030941723212e-6f;
    constexpr float kRoundMagic = 12582912.0f;  // 1.5 * 2^23: adding it rounds to an integer
    constexpr std::int32_t kRoundMagicBits = 0x4B400000;
    const VecF<L> lowest = VecF<L>{} - 87.0f;
    const VecI<L> belowRange = x < lowest;  // off the dependency chain: applied at the end
    x = maxLowest<L>(x, lowest, belowRange);
    const VecF<L> shifted = x * kLog2e + kRoundMagic;
    const VecF<L> n = shifted - kRoundMagic;
    // The integer n sits in the low mantissa bits of `shifted`.
    const VecI<L> exponent = std::bit_cast<VecI<L>>(shifted) - kRoundMagicBits;
    const VecF<L> r = (x - n * kLn2High) - n * kLn2Low;
    // Taylor polynomial of degree 6 (truncation error below 1.2e-7 for |r| <= ln2 / 2),
    // evaluated in Estrin's scheme: a dependency chain of 4 operations instead of Horner's 7,
    // which matters because the filter's loop is bound by this chain's latency.
    const VecF<L> r2 = r * r;
    const VecF<L> low = r + 1.0f;
    const VecF<L> middle = r * (1.0f / 6.0f) + 0.5f;
    const VecF<L> high = (r2 * (1.0f / 720.0f) + (r * (1.0f / 120.0f) + 1.0f / 24.0f));
    const VecF<L> p = r2 * (r2 * high + middle) + low;
    const VecI<L> scaleBits = (exponent + 127) << 23;
    return belowRange ? VecF<L>{} : p * std::bit_cast<VecF<L>>(scaleBits);
}

inline Vec8f fastExpNonPositive(Vec8f x) { return fastExpNonPositiveLanes<8>(x); }

// 1 / (1 + exp(-x)) on eight lanes, through exp(-|x|) so that the exponential's argument is
// never positive: for x < 0 it is exp(x) / (1 + exp(x)). Relative error about 3e-7.
inline Vec8f fastSigmoid(Vec8f x) {
    const Vec8f negativeMagnitude = std::bit_cast<Vec8f>(std::bit_cast<Vec8i>(x) | (Vec8i{} + INT32_MIN));  // -|x|
    const Vec8f e = fastExpNonPositive(negativeMagnitude);
    const Vec8f r = 1.0f / (1.0f + e);
    return x >= 0.0f ? r : e * r;
}

}  // namespace
}  // namespace affinity
