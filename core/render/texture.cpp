#include "render/texture.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "render/rng.h"

namespace affinity::render {
namespace {

constexpr int kNoiseOctaves = 4;
// Far beyond any sensible scene coordinate; keeps the float -> integer lattice conversion
// defined (and NaN harmless) for garbage input.
constexpr double kLatticeLimit = 1e9;

double sanitizeCoordinate(double x) { return std::isfinite(x) ? std::clamp(x, -kLatticeLimit, kLatticeLimit) : 0.0; }

// Value in [0, 1) attached to an integer lattice point of one octave.
double latticeValue(std::int64_t x, std::int64_t y, std::int64_t z, int octave) {
    std::uint64_t h = mix64(std::uint64_t(octave) ^ 0x6a09e667f3bcc909ull);
    h = mix64(h ^ std::uint64_t(x));
    h = mix64(h ^ std::uint64_t(y));
    h = mix64(h ^ std::uint64_t(z));
    return double(h >> 11) * 0x1p-53;
}

// Quintic fade 6t^5 - 15t^4 + 10t^3: C2 across lattice cells, so no visible grid creases.
double fade(double t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); }

double lerp(double a, double b, double t) { return a + (b - a) * t; }

// Trilinear interpolation of lattice values with faded weights; a convex combination, so the
// result stays in [0, 1).
double valueNoise(const glm::dvec3& p, int octave) {
    const glm::dvec3 cell = glm::floor(p);
    const glm::dvec3 f = p - cell;
    const auto x0 = std::int64_t(cell.x);
    const auto y0 = std::int64_t(cell.y);
    const auto z0 = std::int64_t(cell.z);
    const double u = fade(f.x);
    const double v = fade(f.y);
    const double w = fade(f.z);
    double corners[2][2];
    for (int dz = 0; dz < 2; ++dz) {
        for (int dy = 0; dy < 2; ++dy) {
            corners[dz][dy] =
                lerp(latticeValue(x0, y0 + dy, z0 + dz, octave), latticeValue(x0 + 1, y0 + dy, z0 + dz, octave), u);
        }
    }
    return lerp(lerp(corners[0][0], corners[0][1], v), lerp(corners[1][0], corners[1][1], v), w);
}

// Octaves at doubling frequency and halving amplitude, normalised back to [0, 1].
double fractalNoise(const glm::dvec3& p) {
    double sum = 0.0;
    double amplitudeSum = 0.0;
    double amplitude = 1.0;
    double frequency = 1.0;
    for (int octave = 0; octave < kNoiseOctaves; ++octave) {
        const glm::dvec3 q(sanitizeCoordinate(p.x * frequency), sanitizeCoordinate(p.y * frequency),
                           sanitizeCoordinate(p.z * frequency));
        sum += amplitude * valueNoise(q, octave);
        amplitudeSum += amplitude;
        amplitude *= 0.5;
        frequency *= 2.0;
    }
    return std::clamp(sum / amplitudeSum, 0.0, 1.0);
}

bool checkerIsOdd(const glm::vec2& uv, float scale) {
    const double s = std::floor(double(uv.x) * scale) + std::floor(double(uv.y) * scale);
    if (!std::isfinite(s)) return false;
    // Parity for negative cells too (fmod would give -1 there).
    return s - 2.0 * std::floor(s * 0.5) != 0.0;
}

}  // namespace

glm::vec3 Texture::evaluate(const glm::vec2& uv, const glm::vec3& objectPosition) const {
    switch (type) {
    case TextureType::Constant:
        return colorA;
    case TextureType::Checker:
        return checkerIsOdd(uv, scale) ? colorB : colorA;
    case TextureType::Noise: {
        const auto t = float(fractalNoise(glm::dvec3(objectPosition) * double(scale)));
        // Clamped so that float rounding cannot step outside the documented range.
        return glm::clamp(colorA + (colorB - colorA) * t, glm::min(colorA, colorB), glm::max(colorA, colorB));
    }
    }
    return colorA;
}

}  // namespace affinity::render
