#pragma once
#include <string>

// The arithmetic of the convolutions' products. Float32 (the default) is the training
// framework's function within 1e-4 (the parity test). BFloat16 rounds the inputs and weights of
// the Winograd convolutions' products and of the embedding's per-sample layer to 8 significant
// bits and keeps sums in FP32, for twice the multiply-add rate on CPUs with AVX512-BF16 (Zen 4
// and later, Intel Cooper Lake / Sapphire Rapids and later): measured on the benchmark's scenes
// it changes SMAPE and temporal error by well under 1 % (docs/MODEL.md section 10).
namespace affinity {

enum class Precision { Float32, BFloat16 };

// Whether this build and CPU can compute Precision::BFloat16.
bool bfloat16Supported();

// "fp32" or "bf16", as the CLI and the Python module name them; precisionFromName throws
// affinity::Error on any other name.
const char* precisionName(Precision precision);
Precision precisionFromName(const std::string& name);

}  // namespace affinity
