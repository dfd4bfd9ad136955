#include "pipeline/light_restoration.h"

#include <algorithm>
#include <cstddef>
#include <utility>

#include "kernels/box_sums.h"
#include "kernels/luminance.h"
#include "pipeline/motion_blend.h"

namespace affinity {
namespace {

constexpr int kBoxPasses = 3;
// The local mean a pixel's noise is measured against: one box pass of this radius per axis.
constexpr int kLocalMeanRadius = 2;

// A one-channel map of the luminance of a 3-channel one.
FeatureMap luminanceMap(const float* rgb, int height, int width, FeatureMapPool& pool) {
    FeatureMap map = pool.take(height, width, 1);
    const std::size_t pixels = std::size_t(height) * std::size_t(width);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(pixels); ++p) map.data()[p] = luminance(rgb + std::size_t(p) * 3);
    return map;
}

// The variance of the blurred luminance `Y` (given unblurred): each pixel's noise read as its
// squared difference to the mean of its 5 x 5 neighbours (texture and edges count as noise too,
// which only shrinks the gain more), blurred, over the pixels a window averages: a Gaussian of
// deviation s averages about 4 pi s^2 pixels' worth, less the share of it outside the image.
FeatureMap blurredVariance(const FeatureMap& Y, FeatureMapPool& pool) {
    const int height = Y.height(), width = Y.width();
    FeatureMap rows = pool.take(height, width, 1), local = pool.take(height, width, 1);
    boxRowsAndColumns(Y, kLocalMeanRadius, rows, local);
    pool.give(rows);
    const std::size_t pixels = std::size_t(height) * std::size_t(width);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(pixels); ++p) {
        const float difference = Y.data()[p] - local.data()[p];
        local.data()[p] = difference * difference;
    }
    blurForLight(local, pool);
    auto inside = [](int i, int n) {
        constexpr int reach = kBoxPasses * kLightBoxRadius;
        return float(std::min(n - 1, i + reach) - std::max(0, i - reach) + 1) / float(2 * reach + 1);
    };
    const float window = 4.0f * 3.14159265f * float(kLightBoxRadius) * float(kLightBoxRadius + 1);
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) *local.pixel(y, x) /= window * inside(y, height) * inside(x, width);
    return local;
}

}  // namespace

void blurForLight(FeatureMap& map, FeatureMapPool& pool) {
    FeatureMap scratch = pool.take(map.height(), map.width(), 1);
    for (int pass = 0; pass < kBoxPasses; ++pass) boxRowsAndColumns(map, kLightBoxRadius, scratch, map);
    pool.give(scratch);
}

void restoreLight(const FeatureMap& noisy, const float* motion, const float* valid, bool useHistory,
                  LightHistory& history, float* radiance, FeatureMapPool& pool) {
    const int height = noisy.height(), width = noisy.width();
    FeatureMap input = luminanceMap(noisy.data(), height, width, pool);
    FeatureMap variance = blurredVariance(input, pool);
    blurForLight(input, pool);
    FeatureMap output = luminanceMap(radiance, height, width, pool);
    blurForLight(output, pool);
    const bool continues = useHistory && history.input.height() == height && history.input.width() == width;
    if (continues) {
        blendAlongMotion(history.input, motion, valid, kLightHistoryWeight, input, pool);
        blendAlongMotion(history.output, motion, valid, kLightHistoryWeight, output, pool);
        blendAlongMotion(history.inputVariance, motion, valid, kLightHistoryWeight, variance, pool, true);
    }
    const std::size_t pixels = std::size_t(height) * std::size_t(width);
    double meanInput = 0.0;
    for (std::size_t p = 0; p < pixels; ++p) meanInput += input.data()[p];
    meanInput /= double(std::max<std::size_t>(pixels, 1));
    // Keeps the ratio of two near-black windows near 1 (the scale of the frame's light).
    const float floor = float(1e-3 * meanInput) + 1e-30f;
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(pixels); ++p) {
        const float below = output.data()[p] + floor;
        const float excess = (input.data()[p] + floor) / below - 1.0f;
        // The ratio's squared standard error; the excess shrunk by how far it stands above it.
        const float error = variance.data()[p] / below / below;  // (below^2 may underflow)
        const float shrink = excess * excess / (excess * excess + error + 1e-30f);
        const float gain = std::clamp(1.0f + excess * shrink, 1.0f / kLightMaxGain, kLightMaxGain);
        for (int c = 0; c < 3; ++c) radiance[std::size_t(p) * 3 + std::size_t(c)] *= gain;
    }
    for (FeatureMap* kept : {&history.input, &history.output, &history.inputVariance})
        if (kept->height() > 0) pool.give(*kept);  // read: their memory serves the next frame
    history.input = std::move(input);
    history.output = std::move(output);
    history.inputVariance = std::move(variance);
}

}  // namespace affinity
