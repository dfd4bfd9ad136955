#pragma once
// Sixteen float lanes (AVX-512F): the wide vector type of the convolution kernel's AVX-512
// path, the same interface as Float8. Only translation units compiled for x86-64-v4 include
// it (conv_kernel_avx512.cpp, the benchmark's peak measurement); the rest of the project is
// built for x86-64-v3 and reaches this code through a run-time CPU check.
#if !defined(__AVX512F__)
#error "simd16.h needs AVX-512F (compile with -march=x86-64-v4)"
#endif
#include <immintrin.h>

namespace affinity {
// Internal linkage: an AVX-512 copy of these inline functions must never be the one the linker
// keeps for an AVX2 translation unit.
namespace {

struct Float16 {
    static constexpr int kLanes = 16;
    __m512 v;

    static Float16 broadcast(const float* p) { return {_mm512_set1_ps(*p)}; }
    static Float16 broadcast(float x) { return {_mm512_set1_ps(x)}; }
    static Float16 load(const float* p) { return {_mm512_load_ps(p)}; }  // 64-byte aligned
    static Float16 loadu(const float* p) { return {_mm512_loadu_ps(p)}; }
    void storeu(float* p) const { _mm512_storeu_ps(p, v); }
    // Loads lanes [0, count), count in 1..16, the rest 0; memory past them is not read.
    static Float16 loadPartial(const float* p, int count) {
        return {_mm512_maskz_loadu_ps(__mmask16((1u << count) - 1u), p)};
    }
    // Stores lanes [0, count), count in 1..16; memory past them is not touched.
    void storePartial(float* p, int count) const { _mm512_mask_storeu_ps(p, __mmask16((1u << count) - 1u), v); }
    friend Float16 fma(Float16 a, Float16 b, Float16 c) { return {_mm512_fmadd_ps(a.v, b.v, c.v)}; }
    // Half-width forms for a vector whose lanes 8-15 are idle, on a 256-bit value (Half): lanes
    // 0-7 computed as at full width by a 256-bit instruction, on Zen 4 half the work of a 512-bit one.
    using Half = __m256;
    static Half loadHalf(const float* p) { return _mm256_load_ps(p); }  // 32-byte aligned
    static Half fmaHalf(Half a, Half b, Half c) { return _mm256_fmadd_ps(a, b, c); }
    // Lanes 0-7 as a 256-bit vector (a register rename), and back with lanes 8-15 zero (may cost
    // a move that clears them: keep it out of inner loops). Shuffles because GCC 12's cast
    // intrinsics trip -Wmaybe-uninitialized.
    Half low() const { return Half(__builtin_shufflevector(v, v, 0, 1, 2, 3, 4, 5, 6, 7)); }
    static Float16 widen(Half x) {
        return {__m512(__builtin_shufflevector(x, Half{}, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15))};
    }
    friend Float16 operator*(Float16 a, Float16 b) { return {_mm512_mul_ps(a.v, b.v)}; }
    friend Float16 operator+(Float16 a, Float16 b) { return {_mm512_add_ps(a.v, b.v)}; }
    friend Float16 operator-(Float16 a, Float16 b) { return {_mm512_sub_ps(a.v, b.v)}; }
    // maskz with every lane: GCC 12's plain _mm512_max_ps trips -Wuninitialized.
    friend Float16 max(Float16 a, Float16 b) { return {_mm512_maskz_max_ps(__mmask16(0xFFFF), a.v, b.v)}; }
};

}  // namespace
}  // namespace affinity
