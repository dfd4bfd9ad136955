#pragma once
// Parts of the trained pipeline switched off at inference, for the ablation rows of the benchmark
// (docs/BENCHMARK.md; Python: affinity_core.Denoiser(ablation=...)). Internal: measuring what a part
// buys is not something a user of the library asks for, so core/include does not offer it.
#include "affinity/denoiser.h"

namespace affinity {

// The defaults run the whole pipeline.
struct Ablation {
    bool useHistory = true;        // false: every frame denoised on its own (single-frame mode)
    bool temporalKernel = true;    // false: the last kernel has no taps into the previous output
    bool allKernels = true;        // false: only the last (widest) kernel filters, K = 1
    bool lightRestoration = true;  // false: the kernels' output as it is (light_restoration.h)
    bool inputFallback = true;     // false: no move back toward the noisy input (input_fallback.h)
    bool peakGuard = true;         // false: no cap on lone unsupported peaks (peak_guard.h)
    bool historyGuard = true;      // false: the temporal taps take bright history too (history_guard.h)
};

// A Denoiser of `model` with the parts `ablation` switches off.
Denoiser ablatedDenoiser(Model model, const Ablation& ablation);

}  // namespace affinity
