#pragma once
// The dilated affinity kernels and the temporal affinity kernel of docs/MODEL.md sections
// 6-7, and bilinear warping by motion vectors (section 3).
#include "feature_map.h"

namespace affinity {

// Per-pixel parameters of one kernel: features f (F channels), bandwidth a, centre weight c
// and, in models with source weights, the weight s of each pixel as a neighbour of others (c and
// s already through their sigmoid; null s: 1 everywhere). a, c and s are single-channel maps.
struct KernelParams {
    const FeatureMap* features;
    const FeatureMap* bandwidth;
    const FeatureMap* centre;
    const FeatureMap* source = nullptr;
};

// One dilated spatial pass: output = normalised affinity-weighted sum of `radiance`, the
// filtered signal (3 channels, or 6 when demodulated: filter_signal.h), over the
// tapSize x tapSize grid with the given dilation.
void affinityFilter(const FeatureMap& radiance, const KernelParams& kernel, int tapSize, int dilation,
                    FeatureMap& output);

// The last pass: the spatial taps as above plus 3x3 temporal taps on the warped previous
// output (as many channels as `radiance`), weighted by
// exp(-b^2 ||f(p) - warpedFeatures(q)||^2) * warpedValid(q).
void affinityFilterTemporal(const FeatureMap& radiance, const KernelParams& kernel, int tapSize, int dilation,
                            const FeatureMap& temporalBandwidth, const FeatureMap& warpedOutput,
                            const FeatureMap& warpedFeatures, const FeatureMap& warpedValid, FeatureMap& output);

// output(p) = bilinear lookup of `previous` at (x + motion.x, y + motion.y), border-clamped.
// motion: height x width x 2 floats (frame layout).
void warpBilinear(const FeatureMap& previous, const float* motion, FeatureMap& output);

}  // namespace affinity
