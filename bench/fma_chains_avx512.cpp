// fma_chains.h with 16-lane AVX-512 vectors: built with -march=x86-64-v4 (bench/CMakeLists.txt).
#include "fma_chains.h"

#include "kernels/simd16.h"

namespace affinity {

float fmaChainsAvx512(long long steps) { return fmaChains<Float16>(steps); }

}  // namespace affinity
