#include "render/path_tracer.h"

#include <algorithm>
#include <cmath>

#include "affinity/error.h"
#include "affinity/features.h"

namespace affinity::render {
namespace {

// Orthonormal basis around a unit normal (Duff et al. 2017).
struct LocalFrame {
    glm::vec3 s, t, n;
    explicit LocalFrame(const glm::vec3& normal) : n(normal) {
        float sign = std::copysign(1.0f, n.z);
        float a = -1.0f / (sign + n.z), b = n.x * n.y * a;
        s = glm::vec3(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
        t = glm::vec3(b, sign + n.y * n.y * a, -n.y);
    }
    glm::vec3 toLocal(const glm::vec3& v) const { return {glm::dot(v, s), glm::dot(v, t), glm::dot(v, n)}; }
    glm::vec3 toWorld(const glm::vec3& v) const { return v.x * s + v.y * t + v.z * n; }
};

float powerHeuristic(float a, float b) {
    float a2 = a * a, b2 = b * b;
    return a2 + b2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

bool isFinite(const glm::vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

// Offsets a ray origin off the surface to the side `direction` leaves on.
glm::vec3 offsetOrigin(const SurfaceHit& hit, const glm::vec3& direction) {
    float scale =
        1e-4f * (1.0f + std::max({std::abs(hit.position.x), std::abs(hit.position.y), std::abs(hit.position.z)}));
    float side = glm::dot(direction, hit.geometricNormal) >= 0.0f ? 1.0f : -1.0f;
    return hit.position + hit.geometricNormal * (scale * side);
}

// Radiance accumulated along one path, routed to the diffuse / specular features.
struct RadianceSplit {
    glm::vec3 diffuse{0.0f}, specular{0.0f};
    // Throughput before v is `specular` only; from v on, both carry their share.
    glm::vec3 throughputDiffuse{0.0f}, throughputSpecular{1.0f};

    void add(const glm::vec3& radiance) {
        glm::vec3 d = throughputDiffuse * radiance, s = throughputSpecular * radiance;
        if (isFinite(d) && isFinite(s)) {
            diffuse += d;
            specular += s;
        }
    }
    glm::vec3 throughput() const { return throughputDiffuse + throughputSpecular; }
};

// The features as the Blender extension maps Cycles' passes (docs/BLENDER.md, "Feature
// mapping"), recorded along the same path. Cycles writes normal, albedo and depth at the first
// vertex whose closures are not specular by its own threshold (GGX alpha <= 0.075) or that has
// no BSDF at all (a pure emitter: normal 0), multiplying the albedo by the specular chain's
// tint; roughness, metallic and transmissive are shader AOVs of the first hit; emissive is a
// miss or an emitting first hit; anything else that reached no BSDF counts as a miss.
struct CyclesFeatures {
    bool hitSomething = false, firstEmits = false, firstMetallic = false, firstTransmissive = false;
    float firstRoughness = 0.0f;
    bool written = false;      // Cycles wrote its denoising features at some vertex
    bool reachedBsdf = false;  // ... at a vertex with a BSDF (else a pure emitter: normal 0)
    bool pastFirstHit = false;
    glm::vec3 normal{0.0f}, albedo{0.0f}, chainTint{1.0f};
    float depth = 0.0f;

    static bool isCyclesSpecular(const Material& material) {
        const bool microfacet = material.type == MaterialType::Conductor || material.type == MaterialType::Dielectric;
        return microfacet && material.roughness * material.roughness <= kCyclesSpecularAlpha;
    }

    void atVertex(int bounce, const Material& material, const Bsdf& bsdf, bool emits, const glm::vec3& facing,
                  float pathLength) {
        if (bounce == 0) {
            hitSomething = true;
            firstEmits = emits;
            firstRoughness = bsdf.featureRoughness();
            firstMetallic = bsdf.isMetallic();
            firstTransmissive = bsdf.isTransmissive();
        }
        if (written) return;
        const glm::vec3 reflectance = bsdf.albedo();
        // Cycles drops closures of zero weight: a black emitter is a pure Emission shader.
        const bool pureEmission =
            material.type == MaterialType::Emitter && std::max({reflectance.x, reflectance.y, reflectance.z}) <= 0.0f;
        if (!pureEmission && isCyclesSpecular(material)) {
            chainTint *= reflectance;
            return;
        }
        written = true;
        reachedBsdf = !pureEmission;
        pastFirstHit = bounce > 0;
        depth = pathLength;
        if (reachedBsdf) {
            normal = facing;
            albedo = glm::clamp(chainTint * reflectance, 0.0f, 1.0f);
        }
    }

    void write(float* features) const {
        const bool miss = !reachedBsdf && !firstEmits;
        for (int c = 0; c < 3; ++c) {
            features[channel::kNormal + c] = normal[c];
            features[channel::kAlbedo + c] = albedo[c];
        }
        features[channel::kDepth] = miss ? 0.0f : depth;
        features[channel::kRoughness] = miss ? 0.0f : firstRoughness;
        features[channel::kEmissive] = (miss || firstEmits) ? 1.0f : 0.0f;
        features[channel::kMetallic] = (!miss && firstMetallic) ? 1.0f : 0.0f;
        features[channel::kTransmissive] = firstTransmissive ? 1.0f : 0.0f;
        features[channel::kSpecularBounce] = (hitSomething && (pastFirstHit || miss)) ? 1.0f : 0.0f;
    }
};

}  // namespace

FeatureConvention parseFeatureConvention(const std::string& name) {
    if (name == "renderer") return FeatureConvention::Renderer;
    if (name == "cycles") return FeatureConvention::Cycles;
    throw Error("feature convention must be renderer or cycles, got '" + name + "'");
}

const char* featureConventionName(FeatureConvention convention) {
    return convention == FeatureConvention::Cycles ? "cycles" : "renderer";
}

int PathTracer::trace(const glm::vec3& cameraOrigin, const glm::vec3& cameraDirection, Pcg32& rng,
                      float* features) const {
    std::fill(features, features + kFeatureCount, 0.0f);
    const Scene& scene = scene_.scene();
    RadianceSplit radiance;
    bool foundFirstNonSpecular = false;
    bool previousWasDelta = true;  // the camera acts like a delta vertex for MIS
    float previousBsdfPdf = 0.0f;
    glm::vec3 previousPosition = cameraOrigin;
    float pathLength = 0.0f;
    bool transmittedBeforeV = false;
    const bool cycles = convention_ == FeatureConvention::Cycles;
    CyclesFeatures cyclesFeatures;

    int rays = 0;
    glm::vec3 origin = cameraOrigin, direction = cameraDirection;
    for (int bounce = 0; bounce <= maxBounces_; ++bounce) {
        std::optional<SurfaceHit> hit = scene_.intersect(origin, direction);
        ++rays;
        if (!hit) {
            float weight = previousWasDelta ? 1.0f : powerHeuristic(previousBsdfPdf, lights_.pdfEnvironment());
            radiance.add(scene.environment.radiance(direction) * weight);
            if (!foundFirstNonSpecular) {
                features[channel::kEmissive] = 1.0f;  // the environment is what v would be
                features[channel::kTransmissive] = transmittedBeforeV ? 1.0f : 0.0f;
            }
            break;
        }
        pathLength += hit->distance;
        const Material& material = scene.materials[hit->material];
        const glm::vec3 wo = -direction;

        // Emission (one-sided: emitters shine towards their outward normal).
        const bool emits = material.type == MaterialType::Emitter && glm::dot(hit->geometricNormal, wo) > 0.0f;
        if (emits) {
            float weight =
                previousWasDelta ? 1.0f : powerHeuristic(previousBsdfPdf, lights_.pdfEmitter(previousPosition, *hit));
            radiance.add(material.emission * weight);
        }

        // Opaque surfaces are two-sided: face them towards the viewer. Glass keeps its outward
        // normal so the BSDF knows whether the ray enters or leaves.
        SurfaceHit surface = *hit;
        const bool opaque = material.type != MaterialType::Dielectric;
        if (opaque && glm::dot(surface.geometricNormal, wo) < 0.0f) {
            surface.geometricNormal = -surface.geometricNormal;
            surface.shadingNormal = -surface.shadingNormal;
        }
        if (glm::dot(surface.shadingNormal, wo) * glm::dot(surface.geometricNormal, wo) <= 0.0f)
            surface.shadingNormal = surface.geometricNormal;  // interpolation went past the silhouette
        const LocalFrame frame(surface.shadingNormal);
        const glm::vec3 woLocal = frame.toLocal(wo);
        const Bsdf bsdf(material, scene.textures[material.texture].evaluate(surface.uv, surface.objectPosition));

        const bool isV = !foundFirstNonSpecular && bsdf.hasNonDeltaLobe();
        const glm::vec3 facing = woLocal.z >= 0.0f ? surface.shadingNormal : -surface.shadingNormal;
        if (cycles) {
            const glm::vec3 emission = material.emission;
            const bool emitsLight = emits && std::max({emission.x, emission.y, emission.z}) > 0.0f;
            cyclesFeatures.atVertex(bounce, material, bsdf, emitsLight, facing, pathLength);
        }
        // Where the radiance splits into diffuse and specular: at v, or (like Cycles' light
        // passes) at the first hit's closures.
        const bool splitsRadiance = cycles ? bounce == 0 : isV;
        if (isV) {
            foundFirstNonSpecular = true;
            glm::vec3 albedo = glm::clamp(bsdf.albedo(), 0.0f, 1.0f);
            for (int c = 0; c < 3; ++c) {
                features[channel::kNormal + c] = facing[c];
                features[channel::kAlbedo + c] = albedo[c];
            }
            features[channel::kDepth] = pathLength;
            features[channel::kRoughness] = bsdf.featureRoughness();
            features[channel::kEmissive] = material.type == MaterialType::Emitter ? 1.0f : 0.0f;
            features[channel::kMetallic] = bsdf.isMetallic() ? 1.0f : 0.0f;
            features[channel::kTransmissive] = (transmittedBeforeV || bsdf.isTransmissive()) ? 1.0f : 0.0f;
        }

        // Next-event estimation.
        if (bsdf.hasNonDeltaLobe() && !lights_.empty()) {
            float uPick = rng.next();
            glm::vec2 u(rng.next(), rng.next());
            LightSample light = lights_.sample(surface.position, uPick, u);
            if (light.pdf > 0.0f) {
                glm::vec3 wiLocal = frame.toLocal(light.direction);
                BsdfValue f = bsdf.evaluate(woLocal, wiLocal);
                glm::vec3 fTotal = f.diffuse + f.specular;
                bool reachesLight = false;
                if (fTotal != glm::vec3(0.0f)) {
                    ++rays;
                    reachesLight = !scene_.occluded(offsetOrigin(surface, light.direction), light.direction,
                                                    light.distance * (1.0f - 1e-3f));
                }
                if (reachesLight) {
                    float weight = powerHeuristic(light.pdf, f.pdf);
                    glm::vec3 scale = light.radiance * (std::abs(wiLocal.z) * weight / light.pdf);
                    if (splitsRadiance) {
                        // At v the BSDF itself decides diffuse versus specular.
                        RadianceSplit atV;
                        atV.throughputDiffuse = radiance.throughputSpecular * f.diffuse;
                        atV.throughputSpecular = radiance.throughputSpecular * f.specular;
                        atV.add(scale);
                        radiance.diffuse += atV.diffuse;
                        radiance.specular += atV.specular;
                    } else {
                        radiance.add(fTotal * scale);
                    }
                }
            }
        }

        // Continue the path.
        float uLobe = rng.next();
        glm::vec2 u(rng.next(), rng.next());
        std::optional<BsdfSample> next = bsdf.sample(woLocal, uLobe, u);
        if (!next) break;
        const glm::vec3 wi = glm::normalize(frame.toWorld(next->wi));
        if (splitsRadiance) {
            radiance.throughputDiffuse = radiance.throughputSpecular * next->weightDiffuse;
            radiance.throughputSpecular = radiance.throughputSpecular * next->weightSpecular;
        } else {
            glm::vec3 weight = next->weightDiffuse + next->weightSpecular;
            radiance.throughputDiffuse *= weight;
            radiance.throughputSpecular *= weight;
        }
        if (!foundFirstNonSpecular) {
            if (bounce == 0) features[channel::kSpecularBounce] = 1.0f;
            if (next->transmission) transmittedBeforeV = true;
        }
        previousWasDelta = next->delta;
        previousBsdfPdf = next->pdf;
        previousPosition = surface.position;
        origin = offsetOrigin(surface, wi);
        direction = wi;

        // Russian roulette once the path has had a few bounces to pick up light.
        if (bounce >= 3) {
            glm::vec3 t = radiance.throughput();
            float survive = std::min(0.95f, std::max({t.x, t.y, t.z}));
            if (!(survive > 0.0f) || rng.next() >= survive) break;
            radiance.throughputDiffuse /= survive;
            radiance.throughputSpecular /= survive;
        }
    }
    for (int c = 0; c < 3; ++c) {
        features[channel::kDiffuse + c] = radiance.diffuse[c];
        features[channel::kSpecular + c] = radiance.specular[c];
    }
    if (cycles) cyclesFeatures.write(features);
    return rays;
}

}  // namespace affinity::render
