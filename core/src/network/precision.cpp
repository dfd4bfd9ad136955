#include "affinity/precision.h"

#include "affinity/error.h"
#include "kernels/bf16_gemm.h"

namespace affinity {

bool bfloat16Supported() { return cpuHasAvx512Bf16(); }

Precision resolvePrecision(Precision precision) {
    if (precision != Precision::Auto) return precision;
    return bfloat16Supported() ? Precision::BFloat16 : Precision::Float32;
}

const char* precisionName(Precision precision) {
    switch (precision) {
    case Precision::Auto:
        return "auto";
    case Precision::BFloat16:
        return "bf16";
    case Precision::Float32:
        break;
    }
    return "fp32";
}

Precision precisionFromName(const std::string& name) {
    if (name == "auto") return Precision::Auto;
    if (name == "fp32") return Precision::Float32;
    if (name == "bf16") return Precision::BFloat16;
    throw Error("unknown precision '" + name + "' (expected auto, fp32 or bf16)");
}

}  // namespace affinity
