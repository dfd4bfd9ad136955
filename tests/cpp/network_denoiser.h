#pragma once
// The trained network alone, without the light restoration, the input fallback and the peak guard
// the Denoiser runs after it and the bright-history guard of its temporal taps (docs/MODEL.md
// section 10): what the training framework computes, for the parity tests.
#include <string>

#include "affinity/denoiser.h"
#include "pipeline/ablation.h"

namespace affinity::test {

inline Denoiser networkDenoiser(const std::string& weightsPath) {
    return ablatedDenoiser(
        Model::fromFile(weightsPath, Precision::Float32),
        {.lightRestoration = false, .inputFallback = false, .peakGuard = false, .historyGuard = false});
}

}  // namespace affinity::test
