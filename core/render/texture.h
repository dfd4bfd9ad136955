#pragma once
// Procedural textures: a colour as a function of surface uv and object-space position.
#include <glm/glm.hpp>

namespace affinity::render {

enum class TextureType { Constant, Checker, Noise };

struct Texture {
    TextureType type = TextureType::Constant;
    glm::vec3 colorA{0.8f};  // constant colour; first checker colour; noise low end
    glm::vec3 colorB{0.2f};  // second checker colour; noise high end
    float scale = 1.0f;      // checker: squares per uv unit; noise: frequency in object space

    // Checker uses uv; noise (fractal value noise, 4 octaves) uses object-space position so it
    // does not swim when the object moves. Result is in [min(colorA, colorB), max(...)].
    glm::vec3 evaluate(const glm::vec2& uv, const glm::vec3& objectPosition) const;
};

}  // namespace affinity::render
