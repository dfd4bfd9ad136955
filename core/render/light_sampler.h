#pragma once
// Next-event estimation: picks a light (an emissive triangle, with probability proportional
// to its power, or the environment) and a point on it, and gives the solid-angle density of
// doing so for any direction, which multiple importance sampling needs.
#include <vector>

#include <glm/glm.hpp>

#include "render/embree_scene.h"

namespace affinity::render {

struct LightSample {
    glm::vec3 direction{0.0f};  // unit, from the shading point towards the light
    float distance = 0.0f;      // to the light point; infinite for the environment
    glm::vec3 radiance{0.0f};   // emitted towards the shading point
    float pdf = 0.0f;           // solid angle, including the choice of light; 0 = no sample
};

class LightSampler {
public:
    explicit LightSampler(const EmbreeScene& scene);

    bool empty() const { return !hasEnvironment_ && triangles_.empty(); }
    LightSample sample(const glm::vec3& from, float uPick, const glm::vec2& u) const;
    // Density with which sample() from `from` would pick the emitter point `hit`.
    float pdfEmitter(const glm::vec3& from, const SurfaceHit& hit) const;
    // Density with which sample() would pick `direction` on the environment.
    float pdfEnvironment() const;

private:
    struct EmissiveTriangle {
        int object;
        unsigned primitive;
        float area;
    };
    const EmbreeScene& scene_;
    std::vector<EmissiveTriangle> triangles_;
    std::vector<float> cdf_;                   // over triangles_, normalised to 1
    std::vector<std::vector<float>> pickPmf_;  // [object][primitive]; empty for non-emitters
    bool hasEnvironment_ = false;
    float environmentProbability_ = 0.0f;
};

}  // namespace affinity::render
