// The BSDFs of every MaterialType.
//
// Conventions beyond material.h:
// - Transmission uses the radiance (non-adjoint) convention: light refracted from a medium of
//   index n_i into the medium of wo (index n_o) has its radiance scaled by (n_o / n_i)^2, i.e.
//   the BTDF carries 1 / etap^2 with etap = n_wi / n_wo. Radiance inside glass is therefore
//   higher than outside (L / n^2 is what is conserved), so a camera path that leaves a glass
//   object gains n^2 and one that enters it loses 1 / n^2. Light tracing would need the
//   adjoint BTDF without this factor; nothing in this renderer traces from the lights.
// - Plastic: the coat reflects F(wo.m) of the light through a (white) mirror or GGX lobe; the
//   Lambertian base is seen through the coat twice, so its lobe is
//   colour / pi * (1 - F(cos_o)) * (1 - F(cos_i)). Internal reflections between coat and base
//   are ignored (they would add energy, and dropping them keeps the total <= 1: for a smooth
//   coat the albedo is F_o + (1 - F_o) * colour * (1 - cosine-weighted average of F) <= 1).
// - The GGX lobes are single-scattering: light that would bounce between microfacets is lost,
//   so very rough conductors and glass are darker than their colour (a white conductor of
//   roughness 1 reflects 1 - ln 2 = 31% at normal incidence). No energy compensation is added.
// - Colours are clamped to [0, 1] and roughness to [0, 1] on construction, so that bad scene
//   input cannot create energy or NaN.
// - Delta samples report as pdf the discrete probability of picking their lobe (1 for a
//   mirror); integrators must not use it as a solid-angle density.
#include "render/material.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "affinity/features.h"
#include "render/microfacet.h"

namespace affinity::render {
namespace {

constexpr float kInvPi = std::numbers::inv_pi_v<float>;

// The plastic's lobe choice never starves either lobe completely: the Fresnel-based estimate
// is only a proxy for the coat's real share of the reflected energy.
constexpr float kMinPlasticLobeProbability = 0.1f;

float sanitizeUnit(float v) { return std::isfinite(v) ? std::clamp(v, 0.0f, 1.0f) : 0.0f; }

glm::vec3 sanitizeColor(const glm::vec3& c) { return {sanitizeUnit(c.x), sanitizeUnit(c.y), sanitizeUnit(c.z)}; }

bool isFinite(const glm::vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

// Cosine-weighted direction in the upper hemisphere (Malley: uniform disk lifted up).
glm::vec3 sampleCosineHemisphere(const glm::vec2& u) {
    const float r = std::sqrt(u.x);
    const float phi = 2.0f * std::numbers::pi_v<float> * u.y;
    return {r * std::cos(phi), r * std::sin(phi), std::sqrt(std::max(0.0f, 1.0f - u.x))};
}

glm::vec3 mirrorAboutNormal(const glm::vec3& w) { return {-w.x, -w.y, w.z}; }

// n_wi / n_wo for a transmission event, eta = n_inside / n_outside.
float transmissionEta(const glm::vec3& wo, float eta) { return wo.z > 0.0f ? eta : 1.0f / eta; }

// ---- Lambertian (Diffuse and Emitter) ----

BsdfValue evaluateLambert(const glm::vec3& color, const glm::vec3& wo, const glm::vec3& wi) {
    if (wo.z <= 0.0f || wi.z <= 0.0f) return {};
    return {color * kInvPi, glm::vec3(0.0f), wi.z * kInvPi};
}

std::optional<BsdfSample> sampleLambert(const glm::vec3& color, const glm::vec3& wo, const glm::vec2& u) {
    if (wo.z <= 0.0f) return std::nullopt;
    BsdfSample s;
    s.wi = sampleCosineHemisphere(u);
    if (s.wi.z <= 0.0f) return std::nullopt;
    s.weightDiffuse = color;  // (colour / pi) * cos / (cos / pi)
    s.pdf = s.wi.z * kInvPi;
    return s;
}

// ---- GGX reflection shared by the conductor and the plastic coat ----

struct GgxReflection {
    float dgOver4CosCos = 0.0f;  // D G2 / (4 cos_o cos_i): the BRDF without Fresnel
    float cosOm = 0.0f;          // dot(wo, m), the Fresnel angle
    float pdf = 0.0f;            // VNDF density transformed to wi
};

// wo, wi both in the upper hemisphere.
GgxReflection ggxReflection(const GgxDistribution& ggx, const glm::vec3& wo, const glm::vec3& wi) {
    const glm::vec3 h = wo + wi;
    const float len2 = glm::dot(h, h);
    if (!(len2 > 1e-12f)) return {};
    const glm::vec3 m = h / std::sqrt(len2);
    GgxReflection r;
    r.cosOm = glm::dot(wo, m);
    if (r.cosOm <= 0.0f) return {};
    r.dgOver4CosCos = ggx.d(m) * ggx.g2Reflection(wo, wi) / (4.0f * wo.z * wi.z);
    // dm / dwi = 1 / (4 |wi.m|) for reflection, and wi.m = wo.m.
    r.pdf = ggx.visibleNormalPdf(wo, m) / (4.0f * r.cosOm);
    return r;
}

// ---- Conductor ----

BsdfValue evaluateConductor(const Material& mat, const glm::vec3& f0, const glm::vec3& wo, const glm::vec3& wi) {
    if (wo.z <= 0.0f || wi.z <= 0.0f || mat.roughness < kDeltaRoughness) return {};
    const GgxReflection r = ggxReflection(GgxDistribution::fromRoughness(mat.roughness), wo, wi);
    return {glm::vec3(0.0f), fresnelSchlick(f0, r.cosOm) * r.dgOver4CosCos, r.pdf};
}

std::optional<BsdfSample> sampleConductor(const Material& mat, const glm::vec3& f0, const glm::vec3& wo,
                                          const glm::vec2& u) {
    if (wo.z <= 0.0f) return std::nullopt;
    BsdfSample s;
    if (mat.roughness < kDeltaRoughness) {
        s.wi = mirrorAboutNormal(wo);
        s.weightSpecular = fresnelSchlick(f0, wo.z);
        s.pdf = 1.0f;
        s.delta = true;
        return s;
    }
    const GgxDistribution ggx = GgxDistribution::fromRoughness(mat.roughness);
    const glm::vec3 m = ggx.sampleVisibleNormal(wo, u);
    const float cosOm = glm::dot(wo, m);
    if (cosOm <= 0.0f) return std::nullopt;
    s.wi = reflectAbout(wo, m);
    if (s.wi.z <= 0.0f) return std::nullopt;  // reflected below the horizon: absorbed
    // f cos / pdf = F D G2 / (4 cos_o) / (G1(wo) D / (4 cos_o)) = F G2 / G1(wo).
    const float g2OverG1 = ggx.g2Reflection(wo, s.wi) * (1.0f + ggx.lambda(wo));
    s.weightSpecular = fresnelSchlick(f0, cosOm) * g2OverG1;
    s.pdf = ggx.visibleNormalPdf(wo, m) / (4.0f * cosOm);
    return s;
}

// ---- Dielectric ----

// Rough dielectric of Walter et al. 2007 with the height-correlated G2 (microfacet.h).
BsdfValue evaluateRoughDielectric(const GgxDistribution& ggx, float eta, const glm::vec3& tint, const glm::vec3& wo,
                                  const glm::vec3& wi) {
    const float cosO = wo.z;
    const float cosI = wi.z;
    if (cosO == 0.0f || cosI == 0.0f) return {};
    const bool reflection = cosO * cosI > 0.0f;
    // The generalised half vector: the microfacet normal that maps wo to wi. In double, with
    // the inputs renormalised and etap an exact reciprocal from either side: just inside the
    // critical angle the Fresnel transmittance goes like sqrt(cos - cos_critical), so float
    // rounding of m would show up as errors up to percents and break the generalised
    // reciprocity f(wo, wi) / n_o^2 = f(wi, wo) / n_i^2.
    const double etap = reflection ? 1.0 : (cosO > 0.0f ? double(eta) : 1.0 / double(eta));
    const glm::dvec3 o = glm::normalize(glm::dvec3(wo));
    const glm::dvec3 i = glm::normalize(glm::dvec3(wi));
    glm::dvec3 mD = i * etap + o;
    const double len2 = glm::dot(mD, mD);
    if (!(len2 > 1e-12)) return {};
    mD /= std::sqrt(len2);
    if (mD.z < 0.0) mD = -mD;
    const double cosOm = glm::dot(o, mD);
    const double cosIm = glm::dot(i, mD);
    // Each direction must see the side of the facet that faces its own medium.
    if (cosOm * cosO <= 0.0 || cosIm * cosI <= 0.0) return {};
    const glm::vec3 m(mD);
    const double fresnel = fresnelDielectric(cosOm, eta);
    const float vnPdf = ggx.visibleNormalPdf(wo, m);
    const float d = ggx.d(m);
    BsdfValue v;
    if (reflection) {
        v.specular = glm::vec3(d * ggx.g2Reflection(wo, wi) * float(fresnel) / (4.0f * cosO * cosI));
        v.pdf = vnPdf * float(fresnel / (4.0 * std::abs(cosOm)));
    } else {
        // dm / dwi = |wi.m| / (wi.m + wo.m / etap)^2 (Walter et al. 2007, eq. 17).
        const double s = cosIm + cosOm / etap;
        const auto jacobian = float(std::abs(cosIm) / (s * s));
        const auto transmittance = float(1.0 - fresnel);
        const float f = transmittance * d * ggx.g2Transmission(wo, wi) * float(std::abs(cosOm)) * jacobian /
                        std::abs(cosO * cosI) / float(etap * etap);
        v.specular = tint * f;
        v.pdf = vnPdf * jacobian * transmittance;
    }
    return v;
}

std::optional<BsdfSample> sampleRoughDielectric(const GgxDistribution& ggx, float eta, const glm::vec3& tint,
                                                const glm::vec3& wo, float uLobe, const glm::vec2& u) {
    if (wo.z == 0.0f) return std::nullopt;
    const glm::vec3 m = ggx.sampleVisibleNormal(wo, u);
    const float cosOm = glm::dot(wo, m);
    if (cosOm * wo.z <= 0.0f) return std::nullopt;
    const double fresnel = fresnelDielectric(glm::dot(glm::dvec3(wo), glm::dvec3(m)), eta);
    const float vnPdf = ggx.visibleNormalPdf(wo, m);
    // Both lobes: f cos / pdf = G2 / G1(wo) (times tint / etap^2 for transmission): D, the
    // Jacobian and the Fresnel lobe choice cancel.
    const float oneOverG1 = 1.0f + ggx.lambda(wo);
    BsdfSample s;
    if (uLobe < fresnel) {
        s.wi = reflectAbout(wo, m);
        if (s.wi.z * wo.z <= 0.0f) return std::nullopt;
        s.weightSpecular = glm::vec3(ggx.g2Reflection(wo, s.wi) * oneOverG1);
        s.pdf = vnPdf / (4.0f * std::abs(cosOm)) * float(fresnel);
        return s;
    }
    const float etap = transmissionEta(wo, eta);
    const std::optional<glm::vec3> wi = refractThrough(wo, cosOm > 0.0f ? m : -m, etap);
    if (!wi || wi->z * wo.z >= 0.0f) return std::nullopt;
    s.wi = *wi;
    const float cosIm = glm::dot(s.wi, m);
    const float sum = cosIm + cosOm / etap;
    s.weightSpecular = tint * (ggx.g2Transmission(wo, s.wi) * oneOverG1 / (etap * etap));
    s.pdf = vnPdf * std::abs(cosIm) / (sum * sum) * float(1.0 - fresnel);
    s.transmission = true;
    return s;
}

std::optional<BsdfSample> sampleSmoothDielectric(float eta, const glm::vec3& tint, const glm::vec3& wo, float uLobe) {
    if (wo.z == 0.0f) return std::nullopt;
    const auto fresnel = float(fresnelDielectric(wo.z, eta));
    BsdfSample s;
    s.delta = true;
    if (uLobe < fresnel) {
        s.wi = mirrorAboutNormal(wo);
        s.weightSpecular = glm::vec3(1.0f);  // F / (probability F)
        s.pdf = fresnel;
        return s;
    }
    const float etap = transmissionEta(wo, eta);
    const glm::vec3 n(0.0f, 0.0f, wo.z > 0.0f ? 1.0f : -1.0f);
    const std::optional<glm::vec3> wi = refractThrough(wo, n, etap);
    if (!wi) return std::nullopt;  // only reachable by rounding: F == 1 under TIR
    s.wi = *wi;
    s.weightSpecular = tint / (etap * etap);  // (1 - F) / etap^2 / (probability 1 - F)
    s.pdf = 1.0f - fresnel;
    s.transmission = true;
    return s;
}

// ---- Plastic ----

// Probability of sampling the coat rather than the base, from the Fresnel reflectance at wo
// against the light that reaches the base.
float plasticCoatProbability(const glm::vec3& base, float fresnelO) {
    const float baseShare = (1.0f - fresnelO) * (base.x + base.y + base.z) / 3.0f;
    const float total = fresnelO + baseShare;
    const float p = total > 0.0f ? fresnelO / total : 0.5f;
    return std::clamp(p, kMinPlasticLobeProbability, 1.0f - kMinPlasticLobeProbability);
}

BsdfValue evaluatePlastic(const Material& mat, const glm::vec3& base, const glm::vec3& wo, const glm::vec3& wi) {
    if (wo.z <= 0.0f || wi.z <= 0.0f) return {};
    const auto fresnelO = float(fresnelDielectric(wo.z, mat.ior));
    const auto fresnelI = float(fresnelDielectric(wi.z, mat.ior));
    const float pCoat = plasticCoatProbability(base, fresnelO);
    BsdfValue v;
    v.diffuse = base * (kInvPi * (1.0f - fresnelO) * (1.0f - fresnelI));
    v.pdf = (1.0f - pCoat) * wi.z * kInvPi;
    if (mat.roughness >= kDeltaRoughness) {
        const GgxReflection r = ggxReflection(GgxDistribution::fromRoughness(mat.roughness), wo, wi);
        v.specular = glm::vec3(float(fresnelDielectric(r.cosOm, mat.ior)) * r.dgOver4CosCos);
        v.pdf += pCoat * r.pdf;
    }
    return v;
}

std::optional<BsdfSample> samplePlastic(const Material& mat, const glm::vec3& base, const glm::vec3& wo, float uLobe,
                                        const glm::vec2& u) {
    if (wo.z <= 0.0f) return std::nullopt;
    const auto fresnelO = float(fresnelDielectric(wo.z, mat.ior));
    const float pCoat = plasticCoatProbability(base, fresnelO);
    const bool smooth = mat.roughness < kDeltaRoughness;
    BsdfSample s;
    if (uLobe < pCoat) {
        if (smooth) {
            s.wi = mirrorAboutNormal(wo);
            s.weightSpecular = glm::vec3(fresnelO / pCoat);
            s.pdf = pCoat;
            s.delta = true;
            return s;
        }
        const GgxDistribution ggx = GgxDistribution::fromRoughness(mat.roughness);
        const glm::vec3 m = ggx.sampleVisibleNormal(wo, u);
        if (glm::dot(wo, m) <= 0.0f) return std::nullopt;
        s.wi = reflectAbout(wo, m);
    } else {
        s.wi = sampleCosineHemisphere(u);
    }
    if (s.wi.z <= 0.0f) return std::nullopt;
    // The non-delta lobes overlap, so weigh with the whole mixture density (one-sample MIS):
    // this keeps the estimator unbiased and the weight bounded where the lobes meet.
    const BsdfValue v = evaluatePlastic(mat, base, wo, s.wi);
    if (!(v.pdf > 0.0f)) return std::nullopt;
    s.weightDiffuse = v.diffuse * (s.wi.z / v.pdf);
    s.weightSpecular = v.specular * (s.wi.z / v.pdf);
    s.pdf = v.pdf;
    return s;
}

}  // namespace

Bsdf::Bsdf(const Material& material, const glm::vec3& color) : material_(material), color_(sanitizeColor(color)) {
    // Out-of-range parameters from a scene file must not turn into NaN radiance.
    material_.roughness = std::isfinite(material_.roughness) ? std::clamp(material_.roughness, 0.0f, 1.0f) : 1.0f;
    if (!std::isfinite(material_.ior) || !(material_.ior > 0.0f)) material_.ior = 1.5f;
}

bool Bsdf::hasNonDeltaLobe() const {
    switch (material_.type) {
    case MaterialType::Conductor:
    case MaterialType::Dielectric:
        return material_.roughness >= kDeltaRoughness;
    case MaterialType::Diffuse:
    case MaterialType::Plastic:
    case MaterialType::Emitter:
        return true;
    }
    return true;
}

BsdfValue Bsdf::evaluate(const glm::vec3& wo, const glm::vec3& wi) const {
    BsdfValue v;
    switch (material_.type) {
    case MaterialType::Diffuse:
    case MaterialType::Emitter:
        v = evaluateLambert(color_, wo, wi);
        break;
    case MaterialType::Conductor:
        v = evaluateConductor(material_, color_, wo, wi);
        break;
    case MaterialType::Dielectric:
        if (material_.roughness >= kDeltaRoughness) {
            v = evaluateRoughDielectric(GgxDistribution::fromRoughness(material_.roughness), material_.ior, color_, wo,
                                        wi);
        }
        break;
    case MaterialType::Plastic:
        v = evaluatePlastic(material_, color_, wo, wi);
        break;
    }
    // Degenerate geometry (e.g. a direction in the tangent plane) must not leak NaN.
    if (!isFinite(v.diffuse) || !isFinite(v.specular) || !std::isfinite(v.pdf)) return {};
    return v;
}

std::optional<BsdfSample> Bsdf::sample(const glm::vec3& wo, float uLobe, const glm::vec2& u) const {
    std::optional<BsdfSample> s;
    switch (material_.type) {
    case MaterialType::Diffuse:
    case MaterialType::Emitter:
        s = sampleLambert(color_, wo, u);
        break;
    case MaterialType::Conductor:
        s = sampleConductor(material_, color_, wo, u);
        break;
    case MaterialType::Dielectric:
        if (material_.roughness >= kDeltaRoughness) {
            s = sampleRoughDielectric(GgxDistribution::fromRoughness(material_.roughness), material_.ior, color_, wo,
                                      uLobe, u);
        } else {
            s = sampleSmoothDielectric(material_.ior, color_, wo, uLobe);
        }
        break;
    case MaterialType::Plastic:
        s = samplePlastic(material_, color_, wo, uLobe, u);
        break;
    }
    if (!s) return std::nullopt;
    if (!isFinite(s->weightDiffuse) || !isFinite(s->weightSpecular) || !isFinite(s->wi)) {
        return std::nullopt;
    }
    if (!s->delta && !(s->pdf > 0.0f && std::isfinite(s->pdf))) return std::nullopt;
    return s;
}

glm::vec3 Bsdf::albedo() const { return color_; }

float Bsdf::featureRoughness() const {
    switch (material_.type) {
    case MaterialType::Diffuse:
    case MaterialType::Emitter:
        return 1.0f;
    case MaterialType::Conductor:
    case MaterialType::Dielectric:
    case MaterialType::Plastic:
        break;
    }
    return std::clamp(material_.roughness, kRoughnessFloor, 1.0f);
}

}  // namespace affinity::render
