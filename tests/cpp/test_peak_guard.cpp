// The peak guard after the input fallback (core/src/pipeline/peak_guard.h, docs/MODEL.md section
// 10): which lone bright output pixels it caps, to what, and which it leaves bit for bit.
#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <vector>

#include "kernels/feature_map.h"
#include "kernels/luminance.h"
#include "pipeline/peak_guard.h"

namespace affinity {
namespace {

constexpr int kHeight = 12, kWidth = 16;

// A frame's noisy input: its radiance and the statistics of its samples.
struct Input {
    FeatureMap radiance, meanSquares, emissiveShare;
    int spp = 4;
};

// Grey `value` in every pixel, from 4 samples of that value each (none saw an emitter): a
// support of half the value, so that the cap is 8 x 0.5 = 4 x the input.
Input grey(float value) {
    Input input;
    input.radiance = FeatureMap(kHeight, kWidth, 3);
    input.meanSquares = FeatureMap(kHeight, kWidth, 1);
    input.emissiveShare = FeatureMap(kHeight, kWidth, 1);
    for (std::size_t i = 0; i < std::size_t(kHeight) * kWidth * 3; ++i) input.radiance.data()[i] = value;
    for (std::size_t i = 0; i < std::size_t(kHeight) * kWidth; ++i) {
        input.meanSquares.data()[i] = value * value;
        input.emissiveShare.data()[i] = 0.0f;
    }
    return input;
}

// Pixel (y, x) of `input` with mean `value` from 4 samples: `bright` of them of 4 / bright x
// value, the rest 0; `emitters` of them saw an emitter.
void setInputPixel(Input& input, int y, int x, float value, int bright, int emitters = 0) {
    for (int c = 0; c < 3; ++c) input.radiance.pixel(y, x)[c] = value;
    const float sample = value * 4.0f / float(bright);
    input.meanSquares.pixel(y, x)[0] = float(bright) * sample * sample / 4.0f;
    input.emissiveShare.pixel(y, x)[0] = float(emitters) / 4.0f;
}

long guard(const Input& input, std::vector<float>& output, FeatureMapPool& pool) {
    return guardPeaks(input.radiance, input.meanSquares, input.emissiveShare, input.spp, output.data(), pool);
}

std::vector<float> greyOutput(float value) { return std::vector<float>(std::size_t(kHeight) * kWidth * 3, value); }

float* pixel(std::vector<float>& image, int y, int x) { return image.data() + (std::size_t(y) * kWidth + x) * 3; }

void setPixel(float* rgb, float r, float g, float b) { rgb[0] = r, rgb[1] = g, rgb[2] = b; }

TEST(PeakGuard, CapsALonePeakTheInputDoesNotShowKeepingItsHue) {
    // A firefly of an earlier frame carried forward: 3 on a wall of 0.1 whose input is 0.1 here.
    std::vector<float> output = greyOutput(0.1f);
    setPixel(pixel(output, 5, 7), 3.0f, 1.5f, 0.5f);
    const float before = luminance(pixel(output, 5, 7));
    FeatureMapPool pool;
    EXPECT_EQ(guard(grey(0.1f), output, pool), 1);
    // The cap: the larger of 8 x the input's support of 0.05 and 1.5 x the ring's 0.1.
    const float* capped = pixel(output, 5, 7);
    EXPECT_NEAR(luminance(capped), 0.4f, 1e-6f);
    EXPECT_NEAR(capped[0] / capped[1], 2.0f, 1e-5f);
    EXPECT_NEAR(capped[1] / capped[2], 3.0f, 1e-5f);
    EXPECT_GT(before, 1.7f);  // 0.2126 x 3 + 0.7152 x 1.5 + 0.0722 x 0.5 = 1.75 before
    std::vector<float> rest = output;
    setPixel(pixel(rest, 5, 7), 0.1f, 0.1f, 0.1f);
    EXPECT_EQ(rest, greyOutput(0.1f)) << "every other pixel as it was";
}

TEST(PeakGuard, KeepsAGlintThisFramesInputShows) {
    std::vector<float> output = greyOutput(0.1f);
    setPixel(pixel(output, 5, 7), 3.0f, 3.0f, 3.0f);
    Input input = grey(0.1f);
    setInputPixel(input, 5, 8, 0.8f, 4);  // a neighbour's input, all 4 samples: support 0.4, cap 3.2
    const std::vector<float> before = output;
    FeatureMapPool pool;
    EXPECT_EQ(guard(input, output, pool), 0);
    EXPECT_EQ(output, before);
}

// Sets the pixels of rows [y0, y0 + size) and columns [x0, x0 + size) to grey `value`.
void setBlock(std::vector<float>& image, int y0, int x0, int size, float value) {
    for (int y = y0; y < y0 + size; ++y)
        for (int x = x0; x < x0 + size; ++x) setPixel(pixel(image, y, x), value, value, value);
}

TEST(PeakGuard, TheSupportIsTheLightAtLeastTwoSamplesShowOrAnEmittersAll) {
    EXPECT_FLOAT_EQ(peakSupport(1.0f, 1.0f, 0.0f, 4), 0.5f);                    // 4 samples of 1: 1 - sqrt(1 / 4)
    EXPECT_FLOAT_EQ(peakSupport(1.0f, 1.0f, 0.0f, 16), 0.75f);                  // more samples, more of it
    EXPECT_FLOAT_EQ(peakSupport(1.0f, 4.0f, 0.0f, 4), 0.0f);                    // one sample of 4 holds it all
    EXPECT_FLOAT_EQ(peakSupport(1.0f, 2.0f, 0.0f, 4), 1.0f - std::sqrt(0.5f));  // two samples of 2
    EXPECT_FLOAT_EQ(peakSupport(1.0f, 4.0f, 0.25f, 4), 1.0f);                   // that sample saw an emitter
    EXPECT_FLOAT_EQ(peakSupport(0.0f, 0.0f, 0.0f, 1), 0.0f);
}

TEST(PeakGuard, CapsAFireflyOfThisFrameButNotALampOneSampleSaw) {
    // The kernels kept 2 where one of 4 samples brought 12 (a mean of 3) on a wall of 0.1.
    std::vector<float> output = greyOutput(0.1f);
    setPixel(pixel(output, 5, 7), 2.0f, 2.0f, 2.0f);
    Input input = grey(0.1f);
    setInputPixel(input, 5, 7, 3.0f, 1);
    FeatureMapPool pool;
    std::vector<float> capped = output;
    EXPECT_EQ(guard(input, capped, pool), 1);
    EXPECT_NEAR(luminance(pixel(capped, 5, 7)), 0.4f, 1e-6f);  // 8 x the wall's support of 0.05
    // The same sample on a lamp smaller than the pixel: the input shows it, the pixel stays.
    setInputPixel(input, 5, 7, 3.0f, 1, 1);
    std::vector<float> lamp = output;
    EXPECT_EQ(guard(input, lamp, pool), 0);
    EXPECT_EQ(lamp, output);
}

TEST(PeakGuard, CapsASpotOfTwoByTwoPixelsTheInputDoesNotShow) {
    // Light carried along the motion into a few pixels: judged by the ring 2 pixels away.
    std::vector<float> output = greyOutput(0.1f);
    setBlock(output, 5, 7, 2, 3.0f);
    FeatureMapPool pool;
    EXPECT_EQ(guard(grey(0.1f), output, pool), 4);
    std::vector<float> expected = greyOutput(0.1f);
    setBlock(expected, 5, 7, 2, 0.4f);  // 8 x the input's support of 0.05
    for (std::size_t i = 0; i < expected.size(); ++i) EXPECT_NEAR(output[i], expected[i], 1e-6f) << i;
}

TEST(PeakGuard, KeepsLightWiderThanTheRing) {
    // A 4 x 4 highlight (or a firefly's light the kernels spread) on an input that shows none of
    // it: every pixel of it has a pixel of it 2 away, so none is capped.
    std::vector<float> output = greyOutput(0.1f);
    setBlock(output, 4, 6, 4, 2.5f);
    const std::vector<float> before = output;
    FeatureMapPool pool;
    EXPECT_EQ(guard(grey(0.1f), output, pool), 0);
    EXPECT_EQ(output, before);
    // 1.5 x the ring is the limit: a pixel inside it far above the rest is capped at 3.75.
    setPixel(pixel(output, 5, 7), 6.0f, 6.0f, 6.0f);
    EXPECT_EQ(guard(grey(0.1f), output, pool), 1);
    EXPECT_NEAR(luminance(pixel(output, 5, 7)), 1.5f * 2.5f, 1e-5f);
}

TEST(PeakGuard, CornersUseTheNeighboursInsideTheImageAndBlackStaysBlack) {
    std::vector<float> output = greyOutput(0.0f);
    FeatureMapPool pool;
    EXPECT_EQ(guard(grey(0.0f), output, pool), 0);
    EXPECT_EQ(output, greyOutput(0.0f));
    setPixel(pixel(output, 0, 0), 1.0f, 1.0f, 1.0f);
    setPixel(pixel(output, 0, 2), 0.2f, 0.2f, 0.2f);  // on its ring (inside the image)
    setPixel(pixel(output, kHeight - 1, kWidth - 1), 1.0f, 1.0f, 1.0f);
    EXPECT_EQ(guard(grey(0.0f), output, pool), 2);
    EXPECT_NEAR(luminance(pixel(output, 0, 0)), 0.3f, 1e-6f);            // 1.5 x the ring's 0.2
    EXPECT_EQ(luminance(pixel(output, kHeight - 1, kWidth - 1)), 0.0f);  // nothing around it
}

}  // namespace
}  // namespace affinity
