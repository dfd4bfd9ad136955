// Tests of the procedural textures (texture.h).
#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <tuple>

#include "render/rng.h"
#include "render/texture.h"

namespace affinity::render {
namespace {

Texture makeTexture(TextureType type, float scale) {
    Texture t;
    t.type = type;
    t.colorA = {0.9f, 0.1f, 0.5f};
    t.colorB = {0.2f, 0.7f, 0.5f};
    t.scale = scale;
    return t;
}

TEST(Texture, ConstantIgnoresCoordinates) {
    const Texture t = makeTexture(TextureType::Constant, 3.0f);
    EXPECT_EQ(t.evaluate({0.3f, 0.7f}, {1, 2, 3}), t.colorA);
    EXPECT_EQ(t.evaluate({-5.0f, 9.0f}, {-4, 0, 8}), t.colorA);
}

TEST(Texture, CheckerAlternatesBetweenExactlyTwoColours) {
    const Texture t = makeTexture(TextureType::Checker, 4.0f);  // squares of 0.25 uv
    // Square centres: neighbours along u or v differ, diagonal neighbours agree.
    for (int i = -8; i < 8; ++i) {
        for (int j = -8; j < 8; ++j) {
            const glm::vec2 uv((float(i) + 0.5f) / 4.0f, (float(j) + 0.5f) / 4.0f);
            const glm::vec3 c = t.evaluate(uv, {});
            const glm::vec3 right = t.evaluate(uv + glm::vec2(0.25f, 0.0f), {});
            const glm::vec3 up = t.evaluate(uv + glm::vec2(0.0f, 0.25f), {});
            const glm::vec3 diagonal = t.evaluate(uv + glm::vec2(0.25f, 0.25f), {});
            EXPECT_NE(c, right);
            EXPECT_NE(c, up);
            EXPECT_EQ(c, diagonal);
            // Parity rule, negative cells included.
            EXPECT_EQ(c, ((i + j) % 2 == 0) ? t.colorA : t.colorB) << i << " " << j;
        }
    }
    // Only the two colours ever appear, with about equal frequency.
    Pcg32 rng(1, 2);
    std::set<std::tuple<float, float, float>> seen;
    int countA = 0;
    const int n = 20000;
    for (int k = 0; k < n; ++k) {
        const glm::vec2 uv(rng.next() * 10.0f - 5.0f, rng.next() * 10.0f - 5.0f);
        const glm::vec3 c = t.evaluate(uv, {});
        seen.insert({c.x, c.y, c.z});
        countA += c == t.colorA;
    }
    EXPECT_EQ(seen.size(), 2u);
    EXPECT_NEAR(double(countA) / n, 0.5, 0.02);
}

TEST(Texture, NoiseStaysWithinTheColourRangeAndIsDeterministic) {
    const Texture t = makeTexture(TextureType::Noise, 3.0f);
    const glm::vec3 lo = glm::min(t.colorA, t.colorB), hi = glm::max(t.colorA, t.colorB);
    Pcg32 rng(3, 4);
    for (int k = 0; k < 50000; ++k) {
        const glm::vec3 p(rng.next() * 200.0f - 100.0f, rng.next() * 200.0f - 100.0f, rng.next() * 200.0f - 100.0f);
        const glm::vec3 c = t.evaluate({0.0f, 0.0f}, p);
        for (int ch = 0; ch < 3; ++ch) {
            ASSERT_GE(c[ch], lo[ch]);
            ASSERT_LE(c[ch], hi[ch]);
        }
        ASSERT_EQ(c, t.evaluate({0.9f, 0.1f}, p));  // same input, same output; uv ignored
        // The channel with equal ends stays put.
        ASSERT_EQ(c.z, 0.5f);
    }
    // Garbage positions must not produce NaN.
    const glm::vec3 nanPos(std::nanf(""), 1e30f, -INFINITY);
    const glm::vec3 c = t.evaluate({}, nanPos);
    EXPECT_TRUE(std::isfinite(c.x) && std::isfinite(c.y));
}

TEST(Texture, NoiseIsContinuousAndNotConstant) {
    const Texture t = makeTexture(TextureType::Noise, 2.0f);
    // Map a colour back to the blend factor through the red channel (0.9 -> 0.2).
    auto blend = [&](const glm::vec3& p) { return (t.evaluate({}, p).x - t.colorA.x) / (t.colorB.x - t.colorA.x); };
    Pcg32 rng(5, 6);
    double sum = 0.0, sumSq = 0.0, maxJump = 0.0;
    const int n = 20000;
    for (int k = 0; k < n; ++k) {
        const glm::vec3 p(rng.next() * 50.0f, rng.next() * 50.0f, rng.next() * 50.0f);
        const double v = blend(p);
        sum += v;
        sumSq += v * v;
        // Step 1e-4 object units (1.6e-3 lattice cells at the finest octave).
        const glm::vec3 dir = glm::normalize(glm::vec3(rng.next() - 0.5f, rng.next() - 0.5f, rng.next() - 0.5f));
        maxJump = std::max(maxJump, std::abs(blend(p + 1e-4f * dir) - v));
    }
    const double mean = sum / n;
    const double variance = sumSq / n - mean * mean;
    EXPECT_GT(variance, 0.003);  // clearly a pattern, not a flat colour
    EXPECT_NEAR(mean, 0.5, 0.05);
    // Lipschitz bound: each octave's gradient is at most sqrt(3) * 1.875 * frequency (the
    // fade's steepest slope); weighted by the normalised amplitudes the sum over 4 octaves at
    // scale 2 is 8 sqrt(3) ~ 13.9 per unit, i.e. at most 1.4e-3 over this step.
    EXPECT_LT(maxJump, 1.5e-3);
}

TEST(Texture, NoiseScaleChangesTheFrequency) {
    // Scaling the position by 2 with scale 1 is the same as scale 2.
    const Texture a = makeTexture(TextureType::Noise, 1.0f);
    const Texture b = makeTexture(TextureType::Noise, 2.0f);
    Pcg32 rng(7, 8);
    for (int k = 0; k < 1000; ++k) {
        const glm::vec3 p(rng.next() * 10.0f, rng.next() * 10.0f, rng.next() * 10.0f);
        const glm::vec3 ca = a.evaluate({}, 2.0f * p);
        const glm::vec3 cb = b.evaluate({}, p);
        EXPECT_NEAR(ca.x, cb.x, 1e-5f);
    }
}

}  // namespace
}  // namespace affinity::render
