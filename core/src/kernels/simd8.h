#pragma once
// Eight float lanes: the vector type of the convolution and embedding kernels. AVX2 + FMA
// intrinsics when the target has them (-march=x86-64-v3, the project default); a plain
// array otherwise so other targets still build and give the same maths (fused multiply-add
// everywhere, so results agree bitwise across the two implementations).
#include <cmath>

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#define AFFINITY_SIMD8_AVX2 1
#endif

namespace affinity {

struct Float8 {
    static constexpr int kLanes = 8;

#if AFFINITY_SIMD8_AVX2
    __m256 v;

    static Float8 zero() { return {_mm256_setzero_ps()}; }
    static Float8 broadcast(const float* p) { return {_mm256_broadcast_ss(p)}; }
    static Float8 broadcast(float x) { return {_mm256_set1_ps(x)}; }
    static Float8 load(const float* p) { return {_mm256_load_ps(p)}; }  // 32-byte aligned
    static Float8 loadu(const float* p) { return {_mm256_loadu_ps(p)}; }
    void storeu(float* p) const { _mm256_storeu_ps(p, v); }
    // Lanes [0, count), count in 1..8, of a mask for maskload / maskstore.
    static __m256i prefixMask(int count) {
        alignas(32) static constexpr int kPrefix[16] = {-1, -1, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0};
        return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(kPrefix + 8 - count));
    }
    // Loads lanes [0, count), count in 1..8, the rest 0; memory past them is not read.
    static Float8 loadPartial(const float* p, int count) { return {_mm256_maskload_ps(p, prefixMask(count))}; }
    // Stores lanes [0, count), count in 1..8; memory past them is not touched.
    void storePartial(float* p, int count) const { _mm256_maskstore_ps(p, prefixMask(count), v); }
    // a * b + c with one rounding.
    friend Float8 fma(Float8 a, Float8 b, Float8 c) { return {_mm256_fmadd_ps(a.v, b.v, c.v)}; }
    friend Float8 operator*(Float8 a, Float8 b) { return {_mm256_mul_ps(a.v, b.v)}; }
    friend Float8 operator+(Float8 a, Float8 b) { return {_mm256_add_ps(a.v, b.v)}; }
    friend Float8 operator-(Float8 a, Float8 b) { return {_mm256_sub_ps(a.v, b.v)}; }
    friend Float8 max(Float8 a, Float8 b) { return {_mm256_max_ps(a.v, b.v)}; }
#else
    float v[kLanes];

    static Float8 zero() { return broadcast(0.0f); }
    static Float8 broadcast(const float* p) { return broadcast(*p); }
    static Float8 broadcast(float x) {
        Float8 r;
        for (float& lane : r.v) lane = x;
        return r;
    }
    static Float8 load(const float* p) { return loadu(p); }
    static Float8 loadu(const float* p) {
        Float8 r;
        for (int i = 0; i < kLanes; ++i) r.v[i] = p[i];
        return r;
    }
    void storeu(float* p) const {
        for (int i = 0; i < kLanes; ++i) p[i] = v[i];
    }
    static Float8 loadPartial(const float* p, int count) {
        Float8 r = zero();
        for (int i = 0; i < count; ++i) r.v[i] = p[i];
        return r;
    }
    void storePartial(float* p, int count) const {
        for (int i = 0; i < count; ++i) p[i] = v[i];
    }
    friend Float8 fma(Float8 a, Float8 b, Float8 c) {
        Float8 r;
        for (int i = 0; i < kLanes; ++i) r.v[i] = std::fma(a.v[i], b.v[i], c.v[i]);
        return r;
    }
    friend Float8 operator*(Float8 a, Float8 b) {
        Float8 r;
        for (int i = 0; i < kLanes; ++i) r.v[i] = a.v[i] * b.v[i];
        return r;
    }
    friend Float8 operator+(Float8 a, Float8 b) {
        Float8 r;
        for (int i = 0; i < kLanes; ++i) r.v[i] = a.v[i] + b.v[i];
        return r;
    }
    friend Float8 operator-(Float8 a, Float8 b) {
        Float8 r;
        for (int i = 0; i < kLanes; ++i) r.v[i] = a.v[i] - b.v[i];
        return r;
    }
    // Same operand order as maxps: the second operand when either is NaN.
    friend Float8 max(Float8 a, Float8 b) {
        Float8 r;
        for (int i = 0; i < kLanes; ++i) r.v[i] = a.v[i] > b.v[i] ? a.v[i] : b.v[i];
        return r;
    }
#endif
};

}  // namespace affinity
