#pragma once
// Materials and their BSDFs. Directions live in the local shading frame: +Z is the shading
// normal (pointing out of the object), wo points towards the viewer, wi towards the light,
// both unit length and pointing away from the surface point.
//
// Every BSDF value is split into a diffuse part and a specular part (everything that is not
// the Lambertian lobe); the renderer uses the split to build the diffuse / specular radiance
// features. diffuse + specular is the ordinary BSDF.
#include <optional>

#include <glm/glm.hpp>

namespace affinity::render {

// Below this roughness a conductor, dielectric or plastic coat is treated as perfectly smooth:
// its lobe becomes a delta (mirror reflection / ideal refraction).
inline constexpr float kDeltaRoughness = 0.02f;

enum class MaterialType {
    Diffuse,     // Lambertian, reflectance = colour
    Conductor,   // GGX microfacet metal, Schlick Fresnel with F0 = colour
    Dielectric,  // glass: GGX rough or smooth reflection + refraction, transmission tinted by colour
    Plastic,     // Lambertian base (colour) under a dielectric coat (ior, roughness)
    Emitter,     // Lambertian (colour) that also emits `emission` from its front side (+Z)
};

struct Material {
    MaterialType type = MaterialType::Diffuse;
    int texture = 0;           // index of the colour texture in Scene::textures
    float roughness = 0.5f;    // perceptual roughness in [0, 1]; GGX alpha = roughness^2
    float ior = 1.5f;          // dielectric and plastic coat
    glm::vec3 emission{0.0f};  // Emitter only: emitted radiance
};

struct BsdfSample {
    glm::vec3 wi{0.0f};
    glm::vec3 weightDiffuse{0.0f};   // f_diffuse  * |cos(wi)| / pdf
    glm::vec3 weightSpecular{0.0f};  // f_specular * |cos(wi)| / pdf
    float pdf = 0.0f;                // solid-angle density of wi (for MIS); unused when delta
    bool delta = false;              // wi came from a delta lobe
    bool transmission = false;       // wi is on the other side of the surface from wo
};

struct BsdfValue {
    glm::vec3 diffuse{0.0f};   // f_diffuse(wo, wi), no cosine
    glm::vec3 specular{0.0f};  // f_specular(wo, wi), no cosine; delta lobes contribute nothing
    float pdf = 0.0f;          // density with which sample() returns wi (non-delta lobes only)
};

// A material bound to one shading point (its texture already evaluated).
class Bsdf {
public:
    Bsdf(const Material& material, const glm::vec3& color);

    // False for mirrors and smooth glass: next-event estimation is pointless there.
    bool hasNonDeltaLobe() const;
    // True when every lobe is a delta (the vertex is "specular" in the feature schema).
    bool isDelta() const { return !hasNonDeltaLobe(); }

    BsdfValue evaluate(const glm::vec3& wo, const glm::vec3& wi) const;
    // uLobe picks a lobe, u picks a direction; nullopt when the sample is absorbed/invalid.
    std::optional<BsdfSample> sample(const glm::vec3& wo, float uLobe, const glm::vec2& u) const;

    // Feature values at this point (see features.h): reflectance in [0, 1] (F0 tint for
    // conductors, transmission tint for glass, base colour otherwise), roughness clamped to
    // [kRoughnessFloor, 1] (1 for Lambertian), and the material flags.
    glm::vec3 albedo() const;
    float featureRoughness() const;
    bool isMetallic() const { return material_.type == MaterialType::Conductor; }
    bool isTransmissive() const { return material_.type == MaterialType::Dielectric; }

private:
    Material material_;
    glm::vec3 color_;
};

}  // namespace affinity::render
