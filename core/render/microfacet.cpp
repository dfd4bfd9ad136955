#include "render/microfacet.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace affinity::render {
namespace {

constexpr float kInfinity = std::numeric_limits<float>::infinity();

// ln Gamma(x) for x >= 1. std::lgamma writes the global `signgam`, a data race when the
// renderer's threads call it, so use the recurrence Gamma(x) = Gamma(x + 1) / x to move the
// argument above 8 and Stirling's series there (error ~1e-10, far below float precision).
double logGammaAtLeastOne(double x) {
    double product = 1.0;
    while (x < 8.0) {
        product *= x;
        x += 1.0;
    }
    const double inv = 1.0 / x;
    const double inv2 = inv * inv;
    const double series = inv * (1.0 / 12.0 - inv2 * (1.0 / 360.0 - inv2 * (1.0 / 1260.0)));
    return (x - 0.5) * std::log(x) - x + 0.5 * std::log(2.0 * std::numbers::pi) + series - std::log(product);
}

}  // namespace

GgxDistribution GgxDistribution::fromRoughness(float roughness) {
    const float r = std::isfinite(roughness) ? std::clamp(roughness, 0.0f, 1.0f) : 1.0f;
    return GgxDistribution(r * r);
}

GgxDistribution::GgxDistribution(float alpha) : alpha_(std::isfinite(alpha) ? std::max(alpha, kMinGgxAlpha) : 1.0f) {}

float GgxDistribution::d(const glm::vec3& m) const {
    if (m.z <= 0.0f) return 0.0f;
    // alpha^2 / (pi (cos^2 (alpha^2 - 1) + 1)^2) rewritten with sin^2 = x^2 + y^2 so that
    // there is no 1 - cos^2 cancellation when alpha is tiny and m is close to the normal.
    const float a2 = alpha_ * alpha_;
    const float t = (m.x * m.x + m.y * m.y) / a2 + m.z * m.z;
    return 1.0f / (std::numbers::pi_v<float> * a2 * t * t);
}

float GgxDistribution::lambda(const glm::vec3& w) const {
    const float z2 = w.z * w.z;
    if (z2 <= 0.0f) return kInfinity;
    const float a2Tan2 = alpha_ * alpha_ * (w.x * w.x + w.y * w.y) / z2;
    if (!std::isfinite(a2Tan2)) return kInfinity;
    // (sqrt(1 + x) - 1) / 2 without the cancellation for small x.
    return a2Tan2 / (2.0f * (std::sqrt(1.0f + a2Tan2) + 1.0f));
}

float GgxDistribution::g1(const glm::vec3& w) const { return 1.0f / (1.0f + lambda(w)); }

float GgxDistribution::g2Reflection(const glm::vec3& wo, const glm::vec3& wi) const {
    return 1.0f / (1.0f + lambda(wo) + lambda(wi));
}

float GgxDistribution::g2Transmission(const glm::vec3& wo, const glm::vec3& wi) const {
    // Heights are uniform in the masking CDF C(h): the point is visible from above with
    // probability C^Lo and from below with (1 - C)^Li, so G2 = integral = Beta(1+Lo, 1+Li).
    const float lo = lambda(wo);
    const float li = lambda(wi);
    if (!std::isfinite(lo) || !std::isfinite(li)) return 0.0f;
    const double a = 1.0 + double(lo);
    const double b = 1.0 + double(li);
    const double logBeta = logGammaAtLeastOne(a) + logGammaAtLeastOne(b) - logGammaAtLeastOne(a + b);
    return float(std::exp(logBeta));
}

glm::vec3 GgxDistribution::sampleVisibleNormal(const glm::vec3& wo, const glm::vec2& u) const {
    // Seen from below, the surface is statistically the same surface seen from above with
    // the roles of the sides swapped (point reflection), and the outside normal is unchanged.
    const glm::vec3 v = wo.z < 0.0f ? -wo : wo;
    // Stretch the configuration so that the microsurface becomes a hemisphere of unit
    // roughness; the visible normals of a hemisphere are the projection of a disk.
    const glm::vec3 vh = glm::normalize(glm::vec3(alpha_ * v.x, alpha_ * v.y, v.z));
    const float lenSq = vh.x * vh.x + vh.y * vh.y;
    const glm::vec3 t1 = lenSq > 1e-14f ? glm::vec3(-vh.y, vh.x, 0.0f) / std::sqrt(lenSq) : glm::vec3(1, 0, 0);
    const glm::vec3 t2 = glm::cross(vh, t1);
    const float r = std::sqrt(u.x);
    const float phi = 2.0f * std::numbers::pi_v<float> * u.y;
    const float p1 = r * std::cos(phi);
    float p2 = r * std::sin(phi);
    // The part of the disk behind the hemisphere's horizon (as seen from vh) is hidden:
    // squash the lower half of the disk onto the visible half-ellipse.
    const float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * std::sqrt(std::max(0.0f, 1.0f - p1 * p1)) + s * p2;
    const float p3 = std::sqrt(std::max(0.0f, 1.0f - p1 * p1 - p2 * p2));
    const glm::vec3 nh = p1 * t1 + p2 * t2 + p3 * vh;
    // Unstretch; normals transform with the inverse transpose of the stretch.
    return glm::normalize(glm::vec3(alpha_ * nh.x, alpha_ * nh.y, std::max(1e-6f, nh.z)));
}

float GgxDistribution::visibleNormalPdf(const glm::vec3& wo, const glm::vec3& m) const {
    if (wo.z == 0.0f) return 0.0f;
    const float cosOm = glm::dot(wo, m);
    if (cosOm * wo.z <= 0.0f) return 0.0f;
    return g1(wo) * std::abs(cosOm) * d(m) / std::abs(wo.z);
}

double fresnelDielectric(double cosThetaI, double eta) {
    double cosI = std::clamp(cosThetaI, -1.0, 1.0);
    double e = eta;
    if (cosI < 0.0) {
        e = 1.0 / e;
        cosI = -cosI;
    }
    const double sin2T = (1.0 - cosI * cosI) / (e * e);
    if (sin2T >= 1.0) return 1.0;
    const double cosT = std::sqrt(1.0 - sin2T);
    const double rs = (cosI - e * cosT) / (cosI + e * cosT);
    const double rp = (e * cosI - cosT) / (e * cosI + cosT);
    return 0.5 * (rs * rs + rp * rp);
}

glm::vec3 fresnelSchlick(const glm::vec3& f0, float cosTheta) {
    const float m = 1.0f - std::clamp(std::abs(cosTheta), 0.0f, 1.0f);
    const float m2 = m * m;
    return f0 + (glm::vec3(1.0f) - f0) * (m2 * m2 * m);
}

glm::vec3 reflectAbout(const glm::vec3& w, const glm::vec3& n) { return 2.0f * glm::dot(w, n) * n - w; }

std::optional<glm::vec3> refractThrough(const glm::vec3& w, const glm::vec3& n, float eta) {
    const float cosI = glm::dot(w, n);
    const float sin2T = std::max(0.0f, 1.0f - cosI * cosI) / (eta * eta);
    if (sin2T >= 1.0f) return std::nullopt;
    const float cosT = std::sqrt(1.0f - sin2T);
    return glm::normalize(-w / eta + (cosI / eta - cosT) * n);
}

}  // namespace affinity::render
