// The light restoration after the kernels (core/src/pipeline/light_restoration.h, docs/MODEL.md
// section 10): its blur against a direct sum, and the gain on outputs of known brightness, with
// and without history.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

#include "kernels/feature_map.h"
#include "pipeline/light_restoration.h"

namespace affinity {
namespace {

// One box pass by definition: each pixel the mean of the pixels within `radius` along the axis
// that lie inside the image.
FeatureMap directBox(const FeatureMap& in, int radius, bool alongRows) {
    FeatureMap out(in.height(), in.width(), 1);
    for (int y = 0; y < in.height(); ++y)
        for (int x = 0; x < in.width(); ++x) {
            double sum = 0.0;
            int count = 0;
            for (int d = -radius; d <= radius; ++d) {
                const int xx = alongRows ? x + d : x, yy = alongRows ? y : y + d;
                if (xx < 0 || yy < 0 || xx >= in.width() || yy >= in.height()) continue;
                sum += *in.pixel(yy, xx);
                ++count;
            }
            *out.pixel(y, x) = float(sum / count);
        }
    return out;
}

FeatureMap constantRgb(int height, int width, float r, float g, float b) {
    FeatureMap map(height, width, 3);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            float* p = map.pixel(y, x);
            p[0] = r, p[1] = g, p[2] = b;
        }
    return map;
}

std::vector<float> scaled(const FeatureMap& map, float factor) {
    std::vector<float> values(map.data(), map.data() + std::size_t(map.height()) * map.width() * 3);
    for (float& v : values) v *= factor;
    return values;
}

TEST(LightRestoration, BlurMatchesThreeDirectBoxPasses) {
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> value(0.0f, 5.0f);
    FeatureMap map(70, 90, 1);  // wider than the radius on one side only, narrower on neither
    for (int i = 0; i < 70 * 90; ++i) map.data()[i] = value(rng);
    FeatureMap expected = map;
    for (int pass = 0; pass < 3; ++pass)
        expected = directBox(directBox(expected, kLightBoxRadius, true), kLightBoxRadius, false);
    FeatureMapPool pool;
    blurForLight(map, pool);
    for (int i = 0; i < 70 * 90; ++i) ASSERT_NEAR(map.data()[i], expected.data()[i], 1e-4f) << "pixel " << i;
}

TEST(LightRestoration, BlurKeepsAnImpulsesLightAwayFromTheBorders) {
    // No window of any pass reaches the border: 3 radii of spread plus the last window, per side.
    const int size = 8 * kLightBoxRadius + 21;
    FeatureMap map(size, size, 1);
    std::fill(map.data(), map.data() + size * size, 0.0f);
    *map.pixel(size / 2, size / 2) = 1.0f;
    FeatureMapPool pool;
    blurForLight(map, pool);
    double total = 0.0;
    for (int i = 0; i < size * size; ++i) total += map.data()[i];
    EXPECT_NEAR(total, 1.0, 1e-5);
    // Symmetric, highest at the impulse.
    EXPECT_FLOAT_EQ(*map.pixel(size / 2 - 7, size / 2 + 3), *map.pixel(size / 2 + 3, size / 2 + 7));
    EXPECT_GT(*map.pixel(size / 2, size / 2), *map.pixel(size / 2, size / 2 + 1));
}

// The ratio's floor (a thousandth of the frame's mean light) moves it by less than this.
constexpr float kFloorTolerance = 2e-3f;

TEST(LightRestoration, AnEvenlyDimmedOutputGetsTheInputsLightBack) {
    const FeatureMap noisy = constantRgb(40, 50, 0.2f, 0.5f, 0.1f);
    std::vector<float> output = scaled(noisy, 0.8f);
    LightHistory history;
    FeatureMapPool pool;
    restoreLight(noisy, nullptr, nullptr, false, history, output.data(), pool);
    for (std::size_t i = 0; i < output.size(); ++i)
        ASSERT_NEAR(output[i], noisy.data()[i], kFloorTolerance * noisy.data()[i]) << i;
    // An output with none of the light gets at most kLightMaxGain; a brighter one is dimmed.
    std::vector<float> dark = scaled(noisy, 0.1f), bright = scaled(noisy, 1.25f);
    restoreLight(noisy, nullptr, nullptr, false, history, dark.data(), pool);
    restoreLight(noisy, nullptr, nullptr, false, history, bright.data(), pool);
    EXPECT_NEAR(dark[1], 0.5f * 0.1f * kLightMaxGain, 1e-6f);
    EXPECT_NEAR(bright[1], 0.5f, kFloorTolerance * 0.5f);
}

TEST(LightRestoration, TheRatioIsAccumulatedWhereTheHistoryIsValid) {
    const int height = 20, width = 30;
    const FeatureMap noisy = constantRgb(height, width, 1.0f, 1.0f, 1.0f);
    const std::vector<float> motion(std::size_t(height) * width * 2, 0.0f);
    std::vector<float> valid(std::size_t(height) * width, 1.0f);
    for (int x = 0; x < width; ++x) valid[std::size_t(x)] = 0.0f;  // row 0: disoccluded
    LightHistory history;
    FeatureMapPool pool;
    std::vector<float> first = scaled(noisy, 0.8f);
    restoreLight(noisy, motion.data(), valid.data(), false, history, first.data(), pool);
    std::vector<float> second = scaled(noisy, 1.0f);  // this frame's output has all the light
    restoreLight(noisy, motion.data(), valid.data(), true, history, second.data(), pool);
    // Input 1 on both frames; output 0.8 then 1, weighted kLightHistoryWeight and the rest.
    const float w = kLightHistoryWeight;
    const float expected = 1.0f / (w * 0.8f + (1.0f - w) * 1.0f);
    EXPECT_NEAR(second[(std::size_t(10) * width + 15) * 3], expected, kFloorTolerance * expected);
    EXPECT_NEAR(second[std::size_t(15) * 3], 1.0f, 1e-5f);  // row 0 starts afresh
    // Without the history, or after a size change, the frame stands alone.
    std::vector<float> alone = scaled(noisy, 1.0f);
    restoreLight(noisy, motion.data(), valid.data(), false, history, alone.data(), pool);
    EXPECT_NEAR(alone[(std::size_t(10) * width + 15) * 3], 1.0f, 1e-5f);
}

// Sparse bright samples (mostly 0, a few of 100): the input's blurred light is a noisy estimate.
// A deficit well inside its noise is left alone; one far outside it is mostly given back.
TEST(LightRestoration, ADeficitWithinTheInputsNoiseIsLeftAlone) {
    const int size = 100;
    std::mt19937 rng(7);
    std::bernoulli_distribution firefly(0.01);
    FeatureMap noisy(size, size, 3);
    double total = 0.0;
    for (int i = 0; i < size * size; ++i) {
        const float value = firefly(rng) ? 100.0f : 0.0f;
        for (int c = 0; c < 3; ++c) noisy.data()[i * 3 + c] = value;
        total += value;
    }
    const float mean = float(total / (size * size));
    auto gainAtCentre = [&](float outputShare) {
        const FeatureMap output = constantRgb(size, size, outputShare * mean, outputShare * mean, outputShare * mean);
        std::vector<float> values(output.data(), output.data() + size * size * 3);
        LightHistory history;
        FeatureMapPool pool;
        restoreLight(noisy, nullptr, nullptr, false, history, values.data(), pool);
        return values[(std::size_t(size / 2) * size + size / 2) * 3] / (outputShare * mean);
    };
    const float small = gainAtCentre(0.95f), large = gainAtCentre(0.5f);
    EXPECT_GE(small, 1.0f);
    EXPECT_LT(small, 1.02f);  // the unshrunk gain would be about 1.05
    EXPECT_GT(large, 1.6f);   // about 2 unshrunk
    EXPECT_LE(large, kLightMaxGain);
}

TEST(LightRestoration, ABlackFrameStaysBlack) {
    const FeatureMap noisy = constantRgb(16, 16, 0.0f, 0.0f, 0.0f);
    std::vector<float> output(16 * 16 * 3, 0.0f);
    LightHistory history;
    FeatureMapPool pool;
    restoreLight(noisy, nullptr, nullptr, false, history, output.data(), pool);
    for (float v : output) ASSERT_EQ(v, 0.0f);
}

}  // namespace
}  // namespace affinity
