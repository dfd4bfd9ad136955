#pragma once
// log(1 + x) for finite x >= 0 in a form the compiler vectorises (glibc's log1pf is a scalar
// call, and the embedding needs six per sample). Within a few ulp of the exact value.
#include <bit>
#include <cstdint>

namespace affinity {

// Defined inline so `#pragma omp simd` loops can vectorise it.
inline float log1pNonNegative(float x) {
    const float u = 1.0f + x;
    // u = 2^e * m with m in [sqrt(1/2), sqrt(2)): u >= 1 is always a normal number.
    const std::uint32_t bits = std::bit_cast<std::uint32_t>(u);
    int e = int(bits >> 23) - 127;
    float m = std::bit_cast<float>((bits & 0x007fffffu) | 0x3f800000u);
    const bool high = m > 1.41421356f;
    m = high ? 0.5f * m : m;
    e = high ? e + 1 : e;
    // log(m) = 2 atanh(t), t = (m - 1) / (m + 1), |t| <= 0.172: the series to t^9 leaves a
    // relative error below 1e-8. m - 1 is exact.
    const float t = (m - 1.0f) / (m + 1.0f);
    const float t2 = t * t;
    const float series = 1.0f + t2 * (1.0f / 3 + t2 * (1.0f / 5 + t2 * (1.0f / 7 + t2 * (1.0f / 9))));
    const float logM = 2.0f * t * series;
    // ln 2 split so e * kLn2High is exact (kLn2High has 16 significant bits, e at most 8).
    constexpr float kLn2High = 0.693145751953125f;
    constexpr float kLn2Low = 1.428606820309417e-6f;
    const float fe = float(e);
    const float logU = fe * kLn2High + (fe * kLn2Low + logM);
    // u - 1 is exact; x / (u - 1) corrects for the rounding of 1 + x (Goldberg's trick).
    // When 1 + x rounds to 1, log1p(x) = x to within rounding.
    return u == 1.0f ? x : logU * (x / (u - 1.0f));
}

}  // namespace affinity
