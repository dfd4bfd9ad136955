#pragma once
// The scene at one frame, in world space, behind an Embree BVH: ray queries return everything
// shading needs (position, normals, uv, object-space position, material).
#include <memory>
#include <optional>
#include <vector>

#include <embree3/rtcore.h>
#include <glm/glm.hpp>

#include "render/scene.h"

namespace affinity::render {

struct SurfaceHit {
    float distance = 0.0f;
    glm::vec3 position{0.0f};
    glm::vec3 geometricNormal{0.0f};  // unit, on the same side as the shading normal
    glm::vec3 shadingNormal{0.0f};    // unit, interpolated, pointing out of the object
    glm::vec2 uv{0.0f};
    glm::vec3 objectPosition{0.0f};  // the hit point in the object's own space
    int object = -1;
    int material = -1;
    unsigned primitive = 0;
};

// One object's triangles in world space.
struct WorldMesh {
    std::vector<glm::vec3> positions, normals, objectPositions;
    std::vector<glm::vec2> uvs;
    std::vector<glm::uvec3> triangles;
    glm::mat4 objectToWorld{1.0f};
    int material = 0;
};

class EmbreeScene {
public:
    EmbreeScene(const Scene& scene, float frame);
    ~EmbreeScene();
    EmbreeScene(const EmbreeScene&) = delete;
    EmbreeScene& operator=(const EmbreeScene&) = delete;

    std::optional<SurfaceHit> intersect(const glm::vec3& origin, const glm::vec3& direction,
                                        float maxDistance = 1e30f) const;
    bool occluded(const glm::vec3& origin, const glm::vec3& direction, float maxDistance) const;

    const Scene& scene() const { return scene_; }
    const std::vector<WorldMesh>& meshes() const { return meshes_; }

private:
    const Scene& scene_;
    std::vector<WorldMesh> meshes_;
    RTCScene rtcScene_ = nullptr;
};

// Sets flush-to-zero / denormals-are-zero for the calling thread, as Embree recommends.
void enableFastFloatMode();

}  // namespace affinity::render
