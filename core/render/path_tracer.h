#pragma once
// The path tracer that produces one Monte Carlo sample's 18 features (features.h).
//
// Specular vertices are delta interactions (mirrors, smooth glass: material.h's
// kDeltaRoughness). The first vertex with a non-delta lobe is "v": geometry and material
// features are taken there. Radiance is split at v: light that v scatters through its
// Lambertian lobe (directly via next-event estimation, or along the rest of the path) is
// diffuse; everything else - v's glossy/coat lobes, emission seen directly or through a
// chain of delta vertices, the environment seen directly - is specular.
// Next-event estimation with multiple importance sampling (power heuristic) and Russian
// roulette keep the estimator unbiased.
//
// FeatureConvention::Cycles instead writes the features the Blender extension derives from
// Cycles' passes (docs/BLENDER.md, "Feature mapping"), to measure what those differences cost.
// Only the features change: the path, its random numbers and its total radiance are the same.
#include <string>

#include <glm/glm.hpp>

#include "render/embree_scene.h"
#include "render/light_sampler.h"
#include "render/rng.h"

namespace affinity::render {

enum class FeatureConvention {
    Renderer,  // docs/FEATURES.md: features at v, the first vertex with a non-delta lobe
    Cycles,    // as the Blender extension gets them from Cycles (CyclesFeatures in path_tracer.cpp)
};

// "renderer" or "cycles"; parseFeatureConvention throws affinity::Error for anything else.
FeatureConvention parseFeatureConvention(const std::string& name);
const char* featureConventionName(FeatureConvention convention);

// Cycles counts a closure as specular for its denoising features when GGX alpha <= 0.075
// (docs/BLENDER.md), i.e. roughness^2 <= 0.075: roughness <= 0.274.
inline constexpr float kCyclesSpecularAlpha = 0.075f;

class PathTracer {
public:
    PathTracer(const EmbreeScene& scene, const LightSampler& lights, int maxBounces,
               FeatureConvention convention = FeatureConvention::Renderer)
        : scene_(scene), lights_(lights), maxBounces_(maxBounces), convention_(convention) {}

    // Traces one camera path, writes its kFeatureCount features to `features`, and returns
    // the number of rays it cast (for throughput figures).
    int trace(const glm::vec3& origin, const glm::vec3& direction, Pcg32& rng, float* features) const;

private:
    const EmbreeScene& scene_;
    const LightSampler& lights_;
    int maxBounces_;
    FeatureConvention convention_;
};

}  // namespace affinity::render
