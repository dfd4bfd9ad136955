#pragma once
// The dilated affinity kernels and the temporal affinity kernel of docs/MODEL.md sections
// 6-7.
#include "kernels/conv_kernel.h"
#include "kernels/feature_map.h"

namespace affinity {

// Per-pixel parameters of one kernel: features f (F channels), bandwidth a and centre weight c
// (already through its sigmoid); a and c are single-channel maps.
struct KernelParams {
    const FeatureMap* features;
    const FeatureMap* bandwidth;
    const FeatureMap* centre;
};

// The inputs of the temporal taps of the last pass (docs/MODEL.md section 7).
struct TemporalTaps {
    const FeatureMap* bandwidth;  // b, 1 channel
    const FeatureMap* output;     // the warped previous output, as many channels as the signal
    const FeatureMap* features;   // the warped previous features, F channels
    const FeatureMap* valid;      // the warped validity, 1 channel
    // The bright-history guard (pipeline/history_guard.h): a tap whose warped output's luminance
    // exceeds guardRatio x (the centre's luminance in the filtered signal + guardFloor) gives no
    // weight. guardRatio 0: no guard.
    float guardRatio = 0.0f;
    float guardFloor = 0.0f;
};

// One dilated spatial pass: output = normalised affinity-weighted sum of `radiance`, the
// filtered signal (3 channels, filter_signal.h), over the tapSize x tapSize grid with the given
// dilation.
void affinityFilter(const FeatureMap& radiance, const KernelParams& kernel, int tapSize, int dilation,
                    FeatureMap& output);

// The last pass: the spatial taps as above plus 3x3 temporal taps on the warped previous
// output (as many channels as `radiance`), weighted by
// exp(-b^2 ||f(p) - warpedFeatures(q)||^2) * warpedValid(q) (no bright-history guard).
void affinityFilterTemporal(const FeatureMap& radiance, const KernelParams& kernel, int tapSize, int dilation,
                            const FeatureMap& temporalBandwidth, const FeatureMap& warpedOutput,
                            const FeatureMap& warpedFeatures, const FeatureMap& warpedValid, FeatureMap& output);

// Rows [begin, end) of either pass (temporal null: the spatial one) over an image
// `imageHeight` rows tall, for running the passes band by band (band_schedule.h). Any map may
// be a ring shorter than the image that holds image row y at row y % height(): the pass reads
// its inputs' rows begin - reach .. end - 1 + reach (reach: radius x dilation, 1 for the
// temporal taps) and writes rows begin .. end - 1 of `output`, which must already have the
// image's width and the signal's channels and must not be one of the inputs.
void affinityFilterRows(const FeatureMap& radiance, const KernelParams& kernel, int tapSize, int dilation,
                        const TemporalTaps* temporal, int imageHeight, int begin, int end, FeatureMap& output);
// The same with the given vector width instead of the default (defaultConvIsa()): 8 and 16
// lanes give the same bits (tests compare them). Throws affinity::Error for Avx512 where
// !cpuHasAvx512().
void affinityFilterRows(const FeatureMap& radiance, const KernelParams& kernel, int tapSize, int dilation,
                        const TemporalTaps* temporal, int imageHeight, int begin, int end, FeatureMap& output,
                        ConvIsa isa);

}  // namespace affinity
