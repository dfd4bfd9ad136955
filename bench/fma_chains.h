#pragma once
// The FMA loop that measures the machine's FP32 peak (bench_conv): kFmaChains independent
// chains of fused multiply-adds, long enough apart to hide the FMA latency on every pipe,
// written once over the vector type. bench_conv.cpp instantiates it with Float8 (built like
// the library); fma_chains_avx512.cpp with Float16 (built for x86-64-v4, run only where the
// CPU has AVX-512).

namespace affinity {

inline constexpr int kFmaChains = 12;  // more than latency (4-5) x pipes (2)

#if AFFINITY_BENCH_AVX512
// `steps` rounds of the chains with 16-lane vectors; returns a value that depends on them.
float fmaChainsAvx512(long long steps);
#endif

// Internal linkage: each instruction set's translation unit keeps its own copy.
namespace {

// `steps` rounds of the chains with vectors V; returns a value that depends on them.
// acc = acc * a + b converges (|a| < 1), so the values stay normal however long it runs.
template <class V>
__attribute__((noinline)) float fmaChains(long long steps) {
    V acc[kFmaChains];
    for (int k = 0; k < kFmaChains; ++k) acc[k] = V::broadcast(0.01f * float(k));
    const V a = V::broadcast(0.999f), b = V::broadcast(1e-3f);
    for (long long i = 0; i < steps; ++i)
        for (int k = 0; k < kFmaChains; ++k) acc[k] = fma(acc[k], a, b);
    float lanes[V::kLanes], sum = 0.0f;
    for (int k = 0; k < kFmaChains; ++k) {
        acc[k].storeu(lanes);
        sum += lanes[0] + lanes[V::kLanes - 1];
    }
    return sum;
}

}  // namespace
}  // namespace affinity
