#pragma once
// A map carried from frame to frame along the motion: the statistics of the stages after the
// kernels (the light restoration, the input fallback) average over a few frames this way.
#include "kernels/feature_map.h"
#include "pipeline/feature_map_pool.h"

namespace affinity {

// current = weight * (previous warped bilinearly by `motion`) + (1 - weight) * current where
// `valid`, current elsewhere (one-channel maps of one size). With `squared` the weights are
// squared: the variance of that sum of independent estimates. The warped map comes from `pool`.
void blendAlongMotion(const FeatureMap& previous, const float* motion, const float* valid, float weight,
                      FeatureMap& current, FeatureMapPool& pool, bool squared = false);

}  // namespace affinity
