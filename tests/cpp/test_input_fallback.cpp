// The input fallback after the kernels (core/src/pipeline/input_fallback.h, docs/MODEL.md
// section 10): outputs of known departure from inputs of known noise, with and without history.
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "kernels/feature_map.h"
#include "pipeline/input_fallback.h"

namespace affinity {
namespace {

constexpr int kHeight = 30, kWidth = 40;
constexpr std::size_t kPixels = std::size_t(kHeight) * kWidth;

FeatureMap grey(float value) {
    FeatureMap map(kHeight, kWidth, 3);
    for (std::size_t i = 0; i < kPixels * 3; ++i) map.data()[i] = value;
    return map;
}

// The mean squares of one sample per pixel whose window, of grey `input`, has noise `variance`:
// input^2 + variance in every pixel.
FeatureMap meanSquares(float input, float variance) {
    FeatureMap map(kHeight, kWidth, 1);
    for (std::size_t i = 0; i < kPixels; ++i) map.data()[i] = input * input + variance;
    return map;
}

const std::vector<float> kStill(kPixels * 2, 0.0f), kAllValid(kPixels, 1.0f), kNoneValid(kPixels, 0.0f);

// The second of two frames of grey input `input` (noise `variance` in each) whose kernels gave
// grey `output`: the first frame gives the history, the second is moved.
float fallenBack(float input, float variance, float output) {
    FeatureMap history;
    FeatureMapPool pool;
    std::vector<float> first(kPixels * 3, output), second(kPixels * 3, output);
    fallBackToInput(grey(input), meanSquares(input, variance), 1, kStill.data(), kAllValid.data(), false, history,
                    first.data(), pool);
    EXPECT_EQ(first, std::vector<float>(kPixels * 3, output)) << "a frame without history is left as it is";
    fallBackToInput(grey(input), meanSquares(input, variance), 1, kStill.data(), kAllValid.data(), true, history,
                    second.data(), pool);
    return second[(15 * kWidth + 20) * 3 + 1];
}

TEST(InputFallback, TheWindowHoldsAbout196SamplesAtAnySampleCount) {
    // Side sqrt(196 / spp) rounded to an odd number of pixels, at least 3.
    EXPECT_EQ(fallbackRadius(1), 7);   // (14 - 1) / 2 = 6.5 rounds up: 15 x 15 = 225 samples
    EXPECT_EQ(fallbackRadius(2), 4);   // 9 x 9 x 2 = 162
    EXPECT_EQ(fallbackRadius(4), 3);   // 7 x 7 x 4 = 196
    EXPECT_EQ(fallbackRadius(8), 2);   // 5 x 5 x 8 = 200
    EXPECT_EQ(fallbackRadius(16), 1);  // 3 x 3 x 16 = 144
    EXPECT_EQ(fallbackRadius(64), 1);
}

TEST(InputFallback, KeepsAnOutputWhoseDepartureTheNoiseExplainsBitForBit) {
    // 4 samples per pixel of the truth 1 plus noise of deviation 0.4: pixel means of variance 0.04.
    std::mt19937 rng(5);
    std::normal_distribution<float> deviation(0.0f, 0.4f);
    const int spp = 4;
    FeatureMap noisy(kHeight, kWidth, 3), squares(kHeight, kWidth, 1);
    for (std::size_t p = 0; p < kPixels; ++p) {
        float sum = 0.0f, sumSquares = 0.0f;
        for (int s = 0; s < spp; ++s) {
            const float y = 1.0f + deviation(rng);
            sum += y;
            sumSquares += y * y;
        }
        for (int c = 0; c < 3; ++c) noisy.data()[p * 3 + c] = sum / spp;
        squares.data()[p] = sumSquares / spp;
    }
    const std::vector<float> truth(kPixels * 3, 1.0f);
    FeatureMap history;
    FeatureMapPool pool;
    for (bool useHistory : {false, true}) {
        std::vector<float> radiance = truth;
        fallBackToInput(noisy, squares, spp, kStill.data(), kAllValid.data(), useHistory, history, radiance.data(),
                        pool);
        EXPECT_EQ(radiance, truth);
    }
}

TEST(InputFallback, APixelWhoseSamplesAllTookOneBrightPathStaysOut) {
    // Both samples of one pixel 5 (no spread within it), the rest of the wall 0.1 in both; the
    // output a smooth 0.15. The pixel stands out of its window: noise, not the output's bias.
    FeatureMap noisy = grey(0.1f), squares = meanSquares(0.1f, 0.0f);
    const std::size_t firefly = 15 * kWidth + 20;
    for (int c = 0; c < 3; ++c) noisy.data()[firefly * 3 + c] = 5.0f;
    squares.data()[firefly] = 25.0f;
    FeatureMap history;
    FeatureMapPool pool;
    for (bool useHistory : {false, true}) {
        std::vector<float> radiance(kPixels * 3, 0.15f);
        fallBackToInput(noisy, squares, 2, kStill.data(), kAllValid.data(), useHistory, history, radiance.data(), pool);
        EXPECT_EQ(radiance[firefly * 3], 0.15f);
    }
}

TEST(InputFallback, TakesTheInputBackWhereEverySampleWasDark) {
    // A shadow whose samples all came back black, filled with light by the kernels.
    EXPECT_EQ(fallenBack(0.0f, 0.0f, 0.3f), 0.0f);
}

TEST(InputFallback, MovesByTheShareOfTheDepartureTheNoiseDoesNotExplain) {
    // D = (2 - 1)^2 = 1, V = 0.01: the share 1 - 8 * 0.01 / 1 = 0.92 of the way to the input.
    EXPECT_NEAR(fallenBack(2.0f, 0.01f, 1.0f), 1.92f, 1e-5f);
    // D = 0.25, V = 0.05: 8 V > D, the output stays.
    EXPECT_EQ(fallenBack(1.5f, 0.05f, 1.0f), 1.0f);
}

TEST(InputFallback, TheNoiseOfEarlierFramesCarriesOverWhereValid) {
    // Frame 1 saw noise 0.1; frame 2's samples show none and its output departs by 1.
    auto secondFrame = [](bool useHistory, const std::vector<float>& valid) {
        FeatureMap history;
        FeatureMapPool pool;
        std::vector<float> first(kPixels * 3, 1.0f), second(kPixels * 3, 1.0f);
        fallBackToInput(grey(1.0f), meanSquares(1.0f, 0.1f), 1, kStill.data(), kAllValid.data(), false, history,
                        first.data(), pool);
        fallBackToInput(grey(2.0f), meanSquares(2.0f, 0.0f), 1, kStill.data(), valid.data(), useHistory, history,
                        second.data(), pool);
        return second[(15 * kWidth + 20) * 3];
    };
    // V = 0.7 * 0.1 + 0.3 * 0 = 0.07: the share 1 - 8 * 0.07 = 0.44.
    EXPECT_NEAR(secondFrame(true, kAllValid), 1.44f, 1e-5f);
    // Not valid: the frame's own noise, none: all the way.
    EXPECT_EQ(secondFrame(true, kNoneValid), 2.0f);
    // No history: the output stays.
    EXPECT_EQ(secondFrame(false, kAllValid), 1.0f);
}

}  // namespace
}  // namespace affinity
