#include "render/scene.h"

#include <glm/gtc/matrix_transform.hpp>

#include "affinity/error.h"

namespace affinity::render {

glm::mat4 Transform::matrix() const {
    glm::mat4 m = glm::translate(glm::mat4(1.0f), translate);
    m = glm::rotate(m, glm::radians(rotateDegrees.z), glm::vec3(0, 0, 1));
    m = glm::rotate(m, glm::radians(rotateDegrees.y), glm::vec3(0, 1, 0));
    m = glm::rotate(m, glm::radians(rotateDegrees.x), glm::vec3(1, 0, 0));
    return glm::scale(m, scale);
}

namespace {

// Index of the key interval holding `frame` and the blend weight inside it.
template <typename Key>
std::pair<std::size_t, float> locate(const std::vector<Key>& keys, float frame) {
    if (frame <= keys.front().frame || keys.size() == 1) return {0, 0.0f};
    for (std::size_t i = 0; i + 1 < keys.size(); ++i) {
        if (frame < keys[i + 1].frame) {
            float span = keys[i + 1].frame - keys[i].frame;
            return {i, (frame - keys[i].frame) / span};
        }
    }
    return {keys.size() - 1, 0.0f};
}

}  // namespace

Transform Object::transformAt(float frame) const {
    auto [i, w] = locate(keys, frame);
    if (w == 0.0f) return keys[i].transform;
    const Transform& a = keys[i].transform;
    const Transform& b = keys[i + 1].transform;
    return {glm::mix(a.translate, b.translate, w), glm::mix(a.rotateDegrees, b.rotateDegrees, w),
            glm::mix(a.scale, b.scale, w)};
}

CameraKey Camera::keyAt(float frame) const {
    auto [i, w] = locate(keys, frame);
    if (w == 0.0f) return keys[i];
    return {frame, glm::mix(keys[i].position, keys[i + 1].position, w),
            glm::mix(keys[i].target, keys[i + 1].target, w)};
}

void Scene::validate() const {
    if (textures.empty()) throw Error("scene '" + name + "' has no textures");
    for (std::size_t i = 0; i < materials.size(); ++i) {
        const Material& m = materials[i];
        if (m.texture < 0 || m.texture >= int(textures.size()))
            throw Error("scene '" + name + "': material " + std::to_string(i) + " refers to a missing texture");
        if (m.roughness < 0.0f || m.roughness > 1.0f)
            throw Error("scene '" + name + "': material " + std::to_string(i) + " has roughness outside [0, 1]");
        if (m.ior < 1.0f || m.ior > 4.0f)
            throw Error("scene '" + name + "': material " + std::to_string(i) +
                        " has an index of refraction outside [1, 4]");
    }
    for (const Object& o : objects) {
        if (o.material < 0 || o.material >= int(materials.size()))
            throw Error("scene '" + name + "': object '" + o.name + "' refers to a missing material");
        if (o.keys.empty()) throw Error("scene '" + name + "': object '" + o.name + "' has no transform");
        for (std::size_t i = 1; i < o.keys.size(); ++i)
            if (o.keys[i].frame <= o.keys[i - 1].frame)
                throw Error("scene '" + name + "': object '" + o.name + "' has keyframes out of order");
    }
    if (camera.keys.empty()) throw Error("scene '" + name + "' has no camera position");
    for (std::size_t i = 1; i < camera.keys.size(); ++i)
        if (camera.keys[i].frame <= camera.keys[i - 1].frame)
            throw Error("scene '" + name + "': camera keyframes out of order");
    if (camera.fovYDegrees <= 0.0f || camera.fovYDegrees >= 180.0f)
        throw Error("scene '" + name + "': camera field of view must be in (0, 180) degrees");
}

}  // namespace affinity::render
