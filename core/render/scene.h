#pragma once
// The in-memory scene: textures, materials, shapes placed by (optionally animated) transforms,
// an environment and an animated camera. Frame-dependent quantities are evaluated here so the
// renderer, the motion vectors and the tests all agree on where things are at frame t.
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "render/material.h"
#include "render/texture.h"

namespace affinity::render {

enum class ShapeType { Sphere, Box, Quad, Cylinder, Disk };

// Translation, then rotation (Euler XYZ in degrees, applied X first), then scale, as usual:
// world = T * Rz * Ry * Rx * S * object.
struct Transform {
    glm::vec3 translate{0.0f};
    glm::vec3 rotateDegrees{0.0f};
    glm::vec3 scale{1.0f};
    glm::mat4 matrix() const;
};

// A transform at a given frame; transforms between keyframes are interpolated linearly and
// held constant outside the keyed range.
struct TransformKey {
    float frame = 0.0f;
    Transform transform;
};

struct Object {
    std::string name;
    ShapeType shape = ShapeType::Sphere;
    int material = 0;
    std::vector<TransformKey> keys;  // at least one
    Transform transformAt(float frame) const;
};

struct CameraKey {
    float frame = 0.0f;
    glm::vec3 position{0.0f, 0.0f, 5.0f};
    glm::vec3 target{0.0f};
};

struct Camera {
    float fovYDegrees = 40.0f;
    glm::vec3 up{0.0f, 1.0f, 0.0f};
    std::vector<CameraKey> keys;  // at least one
    CameraKey keyAt(float frame) const;
};

// Sky radiance as a vertical gradient: bottom colour looking straight down, top colour
// straight up, linear in the direction's y in between. top == bottom gives a constant one.
struct Environment {
    glm::vec3 top{0.0f};
    glm::vec3 bottom{0.0f};
    glm::vec3 radiance(const glm::vec3& direction) const { return glm::mix(bottom, top, 0.5f * (direction.y + 1.0f)); }
    bool isBlack() const { return top == glm::vec3(0.0f) && bottom == glm::vec3(0.0f); }
};

struct Scene {
    std::string name;
    std::vector<Texture> textures;
    std::vector<Material> materials;
    std::vector<Object> objects;
    Environment environment;
    Camera camera;

    // Throws affinity::Error naming the first broken reference (material, texture, keys).
    void validate() const;
};

}  // namespace affinity::render
