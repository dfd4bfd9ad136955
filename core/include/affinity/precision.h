#pragma once
// The arithmetic of the network's products. Float32 (the default) is the training framework's
// function within 1e-4 (the parity test) and the same bits on every x86-64 CPU. BFloat16 rounds
// the factors of the convolutions' and the embedding's products to 8 significant bits and keeps
// sums in FP32, for twice the multiply-add rate on CPUs with AVX512-BF16 (Zen 4 and later, Intel
// Cooper Lake / Sapphire Rapids and later): on the benchmark's scenes SMAPE and temporal error
// move by under 0.6 %, at 0.76-0.78x the time (docs/MODEL.md section 10).
#include <string>

namespace affinity {

enum class Precision { Float32, BFloat16 };

// Whether this build and CPU can compute Precision::BFloat16.
bool bfloat16Supported();

// "fp32" or "bf16", as the CLI and the Python module name them; precisionFromName throws
// affinity::Error on any other name.
const char* precisionName(Precision precision);
Precision precisionFromName(const std::string& name);

}  // namespace affinity
