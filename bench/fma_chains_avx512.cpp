// fma_chains.h with 16-lane AVX-512 vectors: built with -march=x86-64-v4 (bench/CMakeLists.txt).
#include "fma_chains.h"

#include "simd16.h"

namespace affinity {

// acc = acc * a + b converges (|a| < 1), so the values stay normal however long it runs.
__attribute__((noinline)) float fmaChainsAvx512(long long steps) {
    Float16 acc[kFmaChains];
    for (int k = 0; k < kFmaChains; ++k) acc[k] = Float16::broadcast(0.01f * float(k));
    const Float16 a = Float16::broadcast(0.999f), b = Float16::broadcast(1e-3f);
    for (long long i = 0; i < steps; ++i)
        for (int k = 0; k < kFmaChains; ++k) acc[k] = fma(acc[k], a, b);
    float lanes[Float16::kLanes], sum = 0.0f;
    for (int k = 0; k < kFmaChains; ++k) {
        acc[k].storeu(lanes);
        sum += lanes[0] + lanes[15];
    }
    return sum;
}

}  // namespace affinity
