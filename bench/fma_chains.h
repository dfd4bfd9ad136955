#pragma once
// The FMA loop that measures the machine's FP32 peak (bench_conv): kFmaChains independent
// chains of fused multiply-adds, long enough apart to hide the FMA latency on every pipe.
// One version per vector width; the AVX-512 one lives in its own translation unit built for
// x86-64-v4 and runs only where the CPU has it.

namespace affinity {

inline constexpr int kFmaChains = 12;  // more than latency (4-5) x pipes (2)

#if AFFINITY_BENCH_AVX512
// `steps` rounds of the chains with 16-lane vectors; returns a value that depends on them.
// (The AVX2 version is in bench_conv.cpp, built like the library.)
float fmaChainsAvx512(long long steps);
#endif

}  // namespace affinity
