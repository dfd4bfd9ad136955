#include "render/procedural.h"

#include <algorithm>
#include <cmath>

#include <glm/gtc/constants.hpp>

#include "render/rng.h"

namespace affinity::render {
namespace {

// Uniform draws on top of Pcg32 (std distributions differ between standard libraries).
class Draw {
public:
    explicit Draw(std::uint64_t seed) : rng_(mix64(seed), 0x5eedu) {}
    float uniform(float lo, float hi) { return lo + (hi - lo) * rng_.next(); }
    int integer(int lo, int hi) { return lo + int(rng_.next() * float(hi - lo + 1)) % (hi - lo + 1); }
    bool chance(float p) { return rng_.next() < p; }
    glm::vec3 color(float lo, float hi) { return {uniform(lo, hi), uniform(lo, hi), uniform(lo, hi)}; }
    glm::vec3 vec(float lo, float hi) { return color(lo, hi); }

private:
    Pcg32 rng_;
};

int addTexture(Scene& scene, Draw& draw) {
    Texture t;
    float kind = draw.uniform(0.0f, 1.0f);
    t.type = kind < 0.4f ? TextureType::Constant : kind < 0.7f ? TextureType::Checker : TextureType::Noise;
    t.colorA = draw.color(0.05f, 0.95f);
    t.colorB = t.type == TextureType::Constant ? t.colorA : draw.color(0.05f, 0.95f);
    t.scale = t.type == TextureType::Checker ? draw.uniform(2.0f, 16.0f) : draw.uniform(1.0f, 8.0f);
    scene.textures.push_back(t);
    return int(scene.textures.size()) - 1;
}

int addMaterial(Scene& scene, Draw& draw) {
    Material m;
    m.texture = addTexture(scene, draw);
    float kind = draw.uniform(0.0f, 1.0f);
    if (kind < 0.35f) {
        m.type = MaterialType::Diffuse;
    } else if (kind < 0.55f) {
        m.type = MaterialType::Plastic;
        m.roughness = draw.chance(0.3f) ? 0.0f : draw.uniform(0.05f, 0.6f);
        m.ior = draw.uniform(1.3f, 1.7f);
    } else if (kind < 0.8f) {
        m.type = MaterialType::Conductor;
        m.roughness = draw.chance(0.25f) ? 0.0f : draw.uniform(0.05f, 0.7f);
    } else {
        m.type = MaterialType::Dielectric;
        m.roughness = draw.chance(0.5f) ? 0.0f : draw.uniform(0.05f, 0.4f);
        m.ior = draw.uniform(1.3f, 1.8f);
        scene.textures[m.texture] = Texture{TextureType::Constant, draw.color(0.7f, 1.0f), glm::vec3(0.0f), 1.0f};
        scene.textures[m.texture].colorB = scene.textures[m.texture].colorA;
    }
    scene.materials.push_back(m);
    return int(scene.materials.size()) - 1;
}

int addEmitter(Scene& scene, const glm::vec3& emission) {
    Material m;
    m.type = MaterialType::Emitter;
    m.emission = emission;
    Texture black;
    black.colorA = black.colorB = glm::vec3(0.0f);
    scene.textures.push_back(black);
    m.texture = int(scene.textures.size()) - 1;
    scene.materials.push_back(m);
    return int(scene.materials.size()) - 1;
}

// The Sparks variant's emitters, from their own stream of numbers (docs/TRAINING.md "Sparks").
void addSparks(Scene& scene, std::uint64_t seed) {
    Draw draw(seed ^ 0x5a4b5d1e37c0ffeeull);
    const int count = draw.integer(1, 4);
    for (int i = 0; i < count; ++i) {
        // Log-uniform over 400-6,000, so dim glints and blinding sparks are equally common.
        const float energy = 400.0f * std::pow(15.0f, draw.uniform(0.0f, 1.0f));
        const glm::vec3 tint = draw.color(0.5f, 1.0f);
        const glm::vec3 emission = tint * (energy / std::max({tint.x, tint.y, tint.z}));
        Transform start;
        start.translate = {draw.uniform(-3.0f, 3.0f), draw.uniform(0.3f, 3.2f), draw.uniform(-3.0f, 2.0f)};
        start.scale = glm::vec3(draw.uniform(0.01f, 0.04f));
        Transform end = start;
        end.translate += draw.vec(-0.8f, 0.8f);
        scene.objects.push_back({"spark" + std::to_string(i),
                                 ShapeType::Sphere,
                                 addEmitter(scene, emission),
                                 {{0.0f, start}, {kProceduralSpan, end}}});
    }
}

}  // namespace

const char* proceduralPrefix(ProceduralVariant variant) {
    return variant == ProceduralVariant::Sparks ? "procedural-sparks:" : "procedural:";
}

Scene proceduralScene(std::uint64_t seed, ProceduralVariant variant) {
    Draw draw(seed);
    Scene scene;
    scene.name = proceduralPrefix(variant) + std::to_string(seed);
    scene.textures.push_back(Texture{});

    // Ground, and sometimes a back wall: most real shots have large flat receivers.
    scene.objects.push_back(
        {"ground", ShapeType::Quad, addMaterial(scene, draw), {{0.0f, {{0, 0, 0}, {0, 0, 0}, {12, 1, 12}}}}});
    if (draw.chance(0.5f))
        scene.objects.push_back(
            {"wall", ShapeType::Quad, addMaterial(scene, draw), {{0.0f, {{0, 4, -5}, {90, 0, 0}, {12, 1, 4}}}}});

    const ShapeType shapes[] = {ShapeType::Sphere, ShapeType::Box, ShapeType::Cylinder, ShapeType::Sphere};
    int count = draw.integer(3, 9);
    for (int i = 0; i < count; ++i) {
        Object o;
        o.name = "object" + std::to_string(i);
        o.shape = shapes[draw.integer(0, 3)];
        o.material = addMaterial(scene, draw);
        Transform t;
        float size = draw.uniform(0.25f, 1.1f);
        t.scale = glm::vec3(size);
        if (o.shape == ShapeType::Box) t.scale = draw.vec(0.2f, 1.0f);
        if (o.shape == ShapeType::Cylinder && draw.chance(0.5f)) t.scale = {0.04f, draw.uniform(0.8f, 2.0f), 0.04f};
        t.translate = {draw.uniform(-3.0f, 3.0f), t.scale.y, draw.uniform(-3.0f, 2.0f)};
        t.rotateDegrees = {0.0f, draw.uniform(0.0f, 360.0f), 0.0f};
        o.keys.push_back({0.0f, t});
        if (draw.chance(0.3f)) {  // a moving object: disocclusions in the training data
            Transform end = t;
            end.translate += glm::vec3(draw.uniform(-1.5f, 1.5f), 0.0f, draw.uniform(-1.0f, 1.0f));
            end.rotateDegrees.y += draw.uniform(-90.0f, 90.0f);
            o.keys.push_back({kProceduralSpan, end});
        }
        scene.objects.push_back(o);
    }

    // Lights: area lights overhead, sometimes small bright spheres (fireflies), and a sky.
    int areaLights = draw.integer(0, 2);
    for (int i = 0; i < areaLights; ++i) {
        float size = draw.uniform(0.3f, 1.5f);
        glm::vec3 emission = draw.color(0.6f, 1.0f) * draw.uniform(3.0f, 15.0f) / (size * size) * 2.0f;
        scene.objects.push_back({"area_light" + std::to_string(i),
                                 ShapeType::Quad,
                                 addEmitter(scene, emission),
                                 {{0.0f,
                                   {{draw.uniform(-3, 3), draw.uniform(3.5f, 6.0f), draw.uniform(-3, 3)},
                                    {180.0f, 0.0f, 0.0f},
                                    {size, 1.0f, size}}}}});
    }
    if (draw.chance(0.3f)) {
        glm::vec3 emission = draw.color(0.6f, 1.0f) * draw.uniform(50.0f, 400.0f);
        scene.objects.push_back(
            {"small_light",
             ShapeType::Sphere,
             addEmitter(scene, emission),
             {{0.0f,
               {{draw.uniform(-3, 3), draw.uniform(0.5f, 3.0f), draw.uniform(-3, 2)}, {0, 0, 0}, glm::vec3(0.05f)}}}});
    }
    if (areaLights == 0 || draw.chance(0.6f)) {
        float intensity = draw.uniform(0.2f, 1.5f);
        scene.environment.top = draw.color(0.4f, 1.0f) * intensity;
        scene.environment.bottom = draw.color(0.1f, 0.5f) * intensity * 0.3f;
    }

    // Camera on a ring around the origin, translating and turning over the span.
    float angle = draw.uniform(0.0f, 2.0f * glm::pi<float>()), radius = draw.uniform(5.0f, 9.0f);
    glm::vec3 position(radius * std::sin(angle), draw.uniform(0.8f, 3.5f), radius * std::cos(angle));
    glm::vec3 target(draw.uniform(-1, 1), draw.uniform(0.0f, 1.0f), draw.uniform(-1, 1));
    scene.camera.fovYDegrees = draw.uniform(30.0f, 55.0f);
    scene.camera.keys.push_back({0.0f, position, target});
    scene.camera.keys.push_back({kProceduralSpan, position + draw.vec(-1.5f, 1.5f) * glm::vec3(1, 0.3f, 1),
                                 target + draw.vec(-1.0f, 1.0f) * glm::vec3(1, 0.3f, 1)});
    if (variant == ProceduralVariant::Sparks) addSparks(scene, seed);
    scene.validate();
    return scene;
}

}  // namespace affinity::render
