#pragma once
// GGX (Trowbridge-Reitz) microfacet distribution, Smith masking-shadowing, visible-normal
// sampling and the Fresnel / reflection / refraction helpers shared by the materials.
//
// Conventions: local shading frame (+Z = macro normal pointing out of the object), every
// direction unit length and pointing away from the surface. Microfacet normals m always point
// to the outside (m.z > 0); a direction below the surface sees the underside of the facets.
//
// Masking-shadowing is the height-correlated Smith form (Heitz 2014, "Understanding the
// Masking-Shadowing Function"): for reflection G2 = 1 / (1 + L(o) + L(i)), for transmission
// G2 = Beta(1 + L(o), 1 + L(i)), where L is the GGX Smith Lambda. It is more accurate than
// the separable G1(o) G1(i) (it knows that a point low in the surface is both masked and
// shadowed), and both forms are symmetric in o and i, keeping the reflection BRDF reciprocal.
#include <optional>

#include <glm/glm.hpp>

namespace affinity::render {

// GGX alpha never goes below this: D and Lambda stay finite for roughness -> 0.
inline constexpr float kMinGgxAlpha = 1e-4f;

class GgxDistribution {
public:
    // alpha = roughness^2 (the perceptual roughness mapping), clamped to kMinGgxAlpha.
    static GgxDistribution fromRoughness(float roughness);
    explicit GgxDistribution(float alpha);

    float alpha() const { return alpha_; }

    // Normal distribution D(m) (per unit solid angle of m); 0 for m.z <= 0.
    // Normalised so that the projected microfacet area is 1: integral of D(m) m.z dm = 1.
    float d(const glm::vec3& m) const;
    // Smith Lambda(w); symmetric in w.z -> -w.z. Infinite at grazing (w.z = 0).
    float lambda(const glm::vec3& w) const;
    // Smith masking G1(w) = 1 / (1 + Lambda(w)).
    float g1(const glm::vec3& w) const;
    // Height-correlated masking-shadowing for wo, wi on the same side of the surface.
    float g2Reflection(const glm::vec3& wo, const glm::vec3& wi) const;
    // Height-correlated masking-shadowing for wo, wi on opposite sides of the surface.
    float g2Transmission(const glm::vec3& wo, const glm::vec3& wi) const;

    // Samples a microfacet normal m (m.z > 0) from the distribution of normals visible from
    // wo (Heitz 2018): density D_wo(m) = G1(wo) |wo.m| D(m) / |wo.z| over facets facing wo.
    // wo may lie below the surface, it then sees the facets' undersides (dot(wo, m) < 0).
    glm::vec3 sampleVisibleNormal(const glm::vec3& wo, const glm::vec2& u) const;
    // The density of sampleVisibleNormal; 0 when m faces away from wo or wo is grazing.
    float visibleNormalPdf(const glm::vec3& wo, const glm::vec3& m) const;

private:
    float alpha_;
};

// Exact unpolarised Fresnel reflectance of a smooth dielectric interface. eta = n_inside /
// n_outside; cosThetaI = dot(w, n) with n the outside normal, so a negative cosine means the
// light arrives from the inside (the relative index flips). Returns 1 under total internal
// reflection. Double precision: inside the denser medium F is infinitely steep in cosThetaI
// at the critical angle, and 1 - F (the transmittance) would lose its digits in float there.
double fresnelDielectric(double cosThetaI, double eta);

// Schlick's approximation F0 + (1 - F0)(1 - cos)^5 for conductors (F0 = the RGB reflectance
// at normal incidence). |cosTheta| is used, clamped to [0, 1].
glm::vec3 fresnelSchlick(const glm::vec3& f0, float cosTheta);

// Mirror reflection of w about n (w and the result both point away from the surface).
glm::vec3 reflectAbout(const glm::vec3& w, const glm::vec3& n);

// Refraction of w through an interface with normal n on w's side (dot(w, n) > 0) and relative
// index eta = n_transmitted / n_incident. nullopt on total internal reflection.
std::optional<glm::vec3> refractThrough(const glm::vec3& w, const glm::vec3& n, float eta);

}  // namespace affinity::render
