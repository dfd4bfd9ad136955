#include "affinity/precision.h"

#include "affinity/error.h"
#include "kernels/bf16_gemm.h"

namespace affinity {

bool bfloat16Supported() { return cpuHasAvx512Bf16(); }

const char* precisionName(Precision precision) { return precision == Precision::BFloat16 ? "bf16" : "fp32"; }

Precision precisionFromName(const std::string& name) {
    if (name == "fp32") return Precision::Float32;
    if (name == "bf16") return Precision::BFloat16;
    throw Error("unknown precision '" + name + "' (expected fp32 or bf16)");
}

}  // namespace affinity
