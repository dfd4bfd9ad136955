#pragma once
// log(1 + x) for finite x >= 0 on 8 float lanes (glibc's log1pf is a scalar call, and the
// embedding needs six per sample). Within a few ulp of the exact value.
#include <bit>
#include <cstdint>

#include "kernels/fast_exp.h"  // VecF, VecI

namespace affinity {
namespace {

inline Vec8f log1pNonNegative8(Vec8f x) {
    const Vec8f u = x + 1.0f;
    // u = 2^e * m with m in [sqrt(1/2), sqrt(2)): u >= 1 is always a normal number.
    const Vec8i bits = std::bit_cast<Vec8i>(u);
    Vec8i e = ((bits >> 23) & 0xff) - 127;
    Vec8f m = std::bit_cast<Vec8f>((bits & 0x007fffff) | 0x3f800000);
    const Vec8i high = m > 1.41421356f;
    m = high ? m * 0.5f : m;
    e = high ? e + 1 : e;
    // log(m) = 2 atanh(t), t = (m - 1) / (m + 1), |t| <= 0.172: the series to t^9 leaves a
    // relative error below 1e-8. m - 1 is exact.
    const Vec8f t = (m - 1.0f) / (m + 1.0f);
    const Vec8f t2 = t * t;
    const Vec8f series = 1.0f + t2 * (1.0f / 3 + t2 * (1.0f / 5 + t2 * (1.0f / 7 + t2 * (1.0f / 9))));
    const Vec8f logM = 2.0f * t * series;
    // ln 2 split so e * kLn2High is exact (kLn2High has 16 significant bits, e at most 8).
    constexpr float kLn2High = 0.693145751953125f;
    constexpr float kLn2Low = 1.428606820309417e-6f;
    const Vec8f fe = __builtin_convertvector(e, Vec8f);
    const Vec8f logU = fe * kLn2High + (fe * kLn2Low + logM);
    // u - 1 is exact; x / (u - 1) corrects for the rounding of 1 + x (Goldberg's trick).
    // When 1 + x rounds to 1, log1p(x) = x to within rounding.
    const Vec8f corrected = logU * (x / (u - 1.0f));
    return u == 1.0f ? x : corrected;
}

}  // namespace
}  // namespace affinity
