#pragma once
// What the affinity kernels filter (docs/MODEL.md section 6): the noisy radiance, or with albedo
// demodulation the diffuse radiance divided by the albedo beside the specular radiance, so that
// texture detail is multiplied back after filtering instead of having to survive the kernels.
#include "feature_map.h"

namespace affinity {

// Albedo below this divides (and multiplies back) as this: a black surface reflects no diffuse
// light, so nothing is lost, and the quotient stays bounded.
constexpr float kDemodulationFloor = 0.01f;

// sums: Embedding's per-pixel sample sums (diffuse, specular, albedo) over `spp` samples.
// signal: height x width x 3 (radiance) or x 6 (diffuse / max(albedo, floor), specular).
// albedo (demodulation only): the mean albedo, needed to multiply it back.
void makeFilterSignal(const FeatureMap& sums, int spp, bool albedoDemodulation, FeatureMap& signal,
                      FeatureMap& albedo);

// Radiance from a filtered signal: 3 channels as they are, 6 with the albedo multiplied back
// onto the diffuse part. out: pixelCount() x 3 floats.
void radianceFromSignal(const FeatureMap& signal, const FeatureMap& albedo, float* out);

}  // namespace affinity
