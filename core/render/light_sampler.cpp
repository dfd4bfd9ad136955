#include "render/light_sampler.h"

#include <algorithm>

#include <glm/gtc/constants.hpp>

namespace affinity::render {
namespace {

float luminance(const glm::vec3& c) { return 0.2126f * c.r + 0.7152f * c.g + 0.0722f * c.b; }

}  // namespace

LightSampler::LightSampler(const EmbreeScene& scene) : scene_(scene) {
    const Scene& description = scene.scene();
    const auto& meshes = scene.meshes();
    pickPmf_.resize(meshes.size());
    std::vector<float> power;
    for (std::size_t object = 0; object < meshes.size(); ++object) {
        const Material& material = description.materials[meshes[object].material];
        if (material.type != MaterialType::Emitter || luminance(material.emission) <= 0.0f) continue;
        const WorldMesh& mesh = meshes[object];
        pickPmf_[object].assign(mesh.triangles.size(), 0.0f);
        for (std::size_t prim = 0; prim < mesh.triangles.size(); ++prim) {
            const glm::uvec3 t = mesh.triangles[prim];
            float area = 0.5f * glm::length(glm::cross(mesh.positions[t.y] - mesh.positions[t.x],
                                                       mesh.positions[t.z] - mesh.positions[t.x]));
            if (area <= 0.0f) continue;
            triangles_.push_back({int(object), unsigned(prim), area});
            power.push_back(area * luminance(material.emission));
        }
    }
    hasEnvironment_ = !description.environment.isBlack();
    if (hasEnvironment_) environmentProbability_ = triangles_.empty() ? 1.0f : 0.5f;

    float total = 0.0f;
    for (float p : power) total += p;
    float running = 0.0f;
    for (std::size_t i = 0; i < triangles_.size(); ++i) {
        running += power[i];
        cdf_.push_back(running / total);
        pickPmf_[triangles_[i].object][triangles_[i].primitive] = (1.0f - environmentProbability_) * power[i] / total;
    }
    if (!cdf_.empty()) cdf_.back() = 1.0f;
}

LightSample LightSampler::sample(const glm::vec3& from, float uPick, const glm::vec2& u) const {
    LightSample s;
    if (empty()) return s;
    if (uPick < environmentProbability_) {
        // Uniform sphere: the environments we use are smooth gradients.
        float z = 1.0f - 2.0f * u.x, r = std::sqrt(std::max(0.0f, 1.0f - z * z));
        float phi = 2.0f * glm::pi<float>() * u.y;
        s.direction = glm::vec3(r * std::cos(phi), z, r * std::sin(phi));
        s.distance = 1e30f;
        s.radiance = scene_.scene().environment.radiance(s.direction);
        s.pdf = pdfEnvironment();
        return s;
    }
    float uTriangle = (uPick - environmentProbability_) / (1.0f - environmentProbability_);
    std::size_t index = std::min(std::size_t(std::lower_bound(cdf_.begin(), cdf_.end(), uTriangle) - cdf_.begin()),
                                 triangles_.size() - 1);
    const EmissiveTriangle& light = triangles_[index];
    const WorldMesh& mesh = scene_.meshes()[light.object];
    const glm::uvec3 t = mesh.triangles[light.primitive];
    // Uniform point on the triangle.
    float su = std::sqrt(u.x);
    float b0 = 1.0f - su, b1 = u.y * su, b2 = 1.0f - b0 - b1;
    glm::vec3 p = b0 * mesh.positions[t.x] + b1 * mesh.positions[t.y] + b2 * mesh.positions[t.z];
    // The area-to-solid-angle Jacobian needs the true face normal, oriented outwards.
    glm::vec3 n = glm::normalize(
        glm::cross(mesh.positions[t.y] - mesh.positions[t.x], mesh.positions[t.z] - mesh.positions[t.x]));
    if (glm::dot(n, mesh.normals[t.x] + mesh.normals[t.y] + mesh.normals[t.z]) < 0.0f) n = -n;
    glm::vec3 toLight = p - from;
    float distance2 = glm::dot(toLight, toLight);
    if (distance2 <= 0.0f) return s;
    s.distance = std::sqrt(distance2);
    s.direction = toLight / s.distance;
    float cosLight = -glm::dot(n, s.direction);
    if (cosLight <= 0.0f) return s;  // emitters are one-sided
    s.radiance = scene_.scene().materials[mesh.material].emission;
    s.pdf = pickPmf_[light.object][light.primitive] / light.area * distance2 / cosLight;
    return s;
}

float LightSampler::pdfEmitter(const glm::vec3& from, const SurfaceHit& hit) const {
    const std::vector<float>& pmf = pickPmf_[hit.object];
    if (pmf.empty()) return 0.0f;
    const WorldMesh& mesh = scene_.meshes()[hit.object];
    const glm::uvec3 t = mesh.triangles[hit.primitive];
    float area = 0.5f * glm::length(glm::cross(mesh.positions[t.y] - mesh.positions[t.x],
                                               mesh.positions[t.z] - mesh.positions[t.x]));
    glm::vec3 toHit = hit.position - from;
    float distance2 = glm::dot(toHit, toHit);
    float cosLight = -glm::dot(hit.geometricNormal, toHit) / std::sqrt(distance2);
    if (area <= 0.0f || cosLight <= 0.0f) return 0.0f;
    return pmf[hit.primitive] / area * distance2 / cosLight;
}

float LightSampler::pdfEnvironment() const {
    return hasEnvironment_ ? environmentProbability_ / (4.0f * glm::pi<float>()) : 0.0f;
}

}  // namespace affinity::render
