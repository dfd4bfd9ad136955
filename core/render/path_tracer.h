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
#include <glm/glm.hpp>

#include "render/embree_scene.h"
#include "render/light_sampler.h"
#include "render/rng.h"

namespace affinity::render {

class PathTracer {
public:
    PathTracer(const EmbreeScene& scene, const LightSampler& lights, int maxBounces)
        : scene_(scene), lights_(lights), maxBounces_(maxBounces) {}

    // Traces one camera path, writes its kFeatureCount features to `features`, and returns
    // the number of rays it cast (for throughput figures).
    int trace(const glm::vec3& origin, const glm::vec3& direction, Pcg32& rng, float* features) const;

private:
    const EmbreeScene& scene_;
    const LightSampler& lights_;
    int maxBounces_;
};

}  // namespace affinity::render
