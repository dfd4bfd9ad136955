#pragma once
// Small scenes built in code for the renderer tests.
#include "render/scene.h"

namespace affinity::test {

inline render::Scene emptyScene(const char* name) {
    render::Scene s;
    s.name = name;
    s.textures.push_back(render::Texture{});
    s.camera.keys.push_back({0.0f, {0.0f, 0.0f, 5.0f}, {0.0f, 0.0f, 0.0f}});
    return s;
}

inline int addColor(render::Scene& s, glm::vec3 color) {
    render::Texture t;
    t.colorA = t.colorB = color;
    s.textures.push_back(t);
    return int(s.textures.size()) - 1;
}

inline int addMaterial(render::Scene& s, render::MaterialType type, glm::vec3 color, float roughness = 0.5f,
                       float ior = 1.5f, glm::vec3 emission = glm::vec3(0.0f)) {
    render::Material m;
    m.type = type;
    m.texture = addColor(s, color);
    m.roughness = roughness;
    m.ior = ior;
    m.emission = emission;
    s.materials.push_back(m);
    return int(s.materials.size()) - 1;
}

inline void addObject(render::Scene& s, render::ShapeType shape, int material, render::Transform t) {
    s.objects.push_back({"object" + std::to_string(s.objects.size()), shape, material, {{0.0f, t}}});
}

}  // namespace affinity::test
