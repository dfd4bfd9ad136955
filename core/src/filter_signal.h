#pragma once
// What the denoiser accumulates over time and filters (docs/MODEL.md sections 1, 3, 6, 7): the
// noisy radiance, or with albedo demodulation the diffuse radiance divided by the albedo, the
// specular radiance and the albedo itself. The kernels filter the light; the albedo, only
// accumulated, is multiplied back afterwards, so that texture detail need not survive the
// kernels.
#include "feature_map.h"

namespace affinity {

// Albedo below this divides (and multiplies back) as this: the quotient stays bounded, and a
// kernel that spreads a dark pixel's light onto a bright neighbour amplifies it at most 1 / 0.1
// times (with 0.01, fireflies on dark surfaces became bright blotches: relMSE 13 on the
// benchmark's fireflies scene against 1.1 without demodulation, docs/TRAINING.md).
constexpr float kDemodulationFloor = 0.1f;

// sums: Embedding's per-pixel sample sums (diffuse, specular, albedo) over `spp` samples.
// signal: height x width x 3 (radiance) or x 9 (diffuse / max(albedo, floor), specular, albedo).
void makeAccumulatedSignal(const FeatureMap& sums, int spp, bool albedoDemodulation, FeatureMap& signal);

// The part of an accumulated signal the kernels filter (its first 3 or 6 channels) and, for a
// demodulated one, its albedo (the last 3; `albedo` is left alone otherwise).
void splitAccumulatedSignal(const FeatureMap& accumulated, FeatureMap& filtered, FeatureMap& albedo);

// Radiance from a filtered signal: 3 channels as they are, 6 with the albedo multiplied back
// onto the diffuse part. out: pixelCount() x 3 floats.
void radianceFromSignal(const FeatureMap& signal, const FeatureMap& albedo, float* out);

}  // namespace affinity
