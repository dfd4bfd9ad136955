#pragma once
// The arithmetic of the network's products, named the same in C++ (Precision), the CLI
// (`--precision`), Python (`precision=`) and Blender (the panel's Precision): "auto", "fp32" or
// "bf16". BFloat16 rounds the factors of the convolutions' and the embedding's products to 8
// significant bits and keeps sums in FP32, for twice the multiply-add rate on CPUs with
// AVX512-BF16 (Zen 4 and later, Intel Cooper Lake / Sapphire Rapids and later); on the
// benchmark's scenes SMAPE and temporal error stay equal to the fourth digit (docs/MODEL.md,
// "bfloat16 products"). Float32 is the training framework's function within 1e-4 (the parity
// test) and the same bits on every x86-64 CPU. Auto, the default, is BFloat16 where the CPU has
// AVX512-BF16 and Float32 elsewhere; tests that compare with FP32 or libtorch ask for Float32.
#include <string>

namespace affinity {

enum class Precision { Auto, Float32, BFloat16 };

// Whether this build and CPU can compute Precision::BFloat16.
bool bfloat16Supported();

// What a model asked for `precision` computes in: Auto resolved (BFloat16 where
// bfloat16Supported(), else Float32), the others as they are.
Precision resolvePrecision(Precision precision);

// "auto", "fp32" or "bf16", as the CLI, Python and Blender name them; precisionFromName throws
// affinity::Error on any other name.
const char* precisionName(Precision precision);
Precision precisionFromName(const std::string& name);

}  // namespace affinity
