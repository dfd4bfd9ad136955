#include "pipeline/light_restoration.h"

#include <algorithm>
#include <cstddef>
#include <utility>
#include <vector>

#include "kernels/bilinear_warp.h"

namespace affinity {
namespace {

constexpr int kBoxPasses = 3;
constexpr int kColumnBlock = 64;  // columns per work item of the vertical pass
// The local mean a pixel's noise is measured against: one box pass of this radius per axis.
constexpr int kLocalMeanRadius = 2;

float luminance(const float* rgb) { return 0.2126f * rgb[0] + 0.7152f * rgb[1] + 0.0722f * rgb[2]; }

// out[i] = mean of in[j * stride] over |j - i| <= radius inside [0, n): a running sum (in double,
// so that adding and taking away values does not drift).
void boxLine(const float* in, std::size_t stride, int n, int radius, float* out) {
    double sum = 0.0;
    const int first = std::min(radius, n - 1);
    for (int j = 0; j <= first; ++j) sum += in[std::size_t(j) * stride];
    for (int i = 0; i < n; ++i) {
        const int low = std::max(0, i - radius), high = std::min(n - 1, i + radius);
        out[i] = float(sum / double(high - low + 1));
        if (i + radius + 1 < n) sum += in[std::size_t(i + radius + 1) * stride];
        if (i - radius >= 0) sum -= in[std::size_t(i - radius) * stride];
    }
}

void boxRows(FeatureMap& map, int radius) {
    const int width = map.width();
#pragma omp parallel
    {
        std::vector<float> line(static_cast<std::size_t>(width));
#pragma omp for schedule(static)
        for (int y = 0; y < map.height(); ++y) {
            float* row = map.pixel(y, 0);
            boxLine(row, 1, width, radius, line.data());
            std::copy(line.begin(), line.end(), row);
        }
    }
}

void boxColumns(FeatureMap& map, int radius) {
    const int width = map.width(), height = map.height();
    const int blocks = (width + kColumnBlock - 1) / kColumnBlock;
#pragma omp parallel
    {
        std::vector<float> line(static_cast<std::size_t>(height));
#pragma omp for schedule(static)
        for (int block = 0; block < blocks; ++block) {
            const int end = std::min(width, (block + 1) * kColumnBlock);
            for (int x = block * kColumnBlock; x < end; ++x) {
                boxLine(map.pixel(0, x), std::size_t(width), height, radius, line.data());
                for (int y = 0; y < height; ++y) *map.pixel(y, x) = line[std::size_t(y)];
            }
        }
    }
}

// A one-channel map of the luminance of a 3-channel one.
FeatureMap luminanceMap(const float* rgb, int height, int width) {
    FeatureMap map(height, width, 1);
    const std::size_t pixels = std::size_t(height) * std::size_t(width);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(pixels); ++p) map.data()[p] = luminance(rgb + std::size_t(p) * 3);
    return map;
}

// The variance of the blurred luminance `Y` (given unblurred): each pixel's noise read as its
// squared difference to the mean of its 5 x 5 neighbours (texture and edges count as noise too,
// which only shrinks the gain more), blurred, over the pixels a window averages: a Gaussian of
// deviation s averages about 4 pi s^2 pixels' worth, less the share of it outside the image.
FeatureMap blurredVariance(const FeatureMap& Y) {
    const int height = Y.height(), width = Y.width();
    FeatureMap local = Y;
    boxRows(local, kLocalMeanRadius);
    boxColumns(local, kLocalMeanRadius);
    const std::size_t pixels = std::size_t(height) * std::size_t(width);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(pixels); ++p) {
        const float difference = Y.data()[p] - local.data()[p];
        local.data()[p] = difference * difference;
    }
    blurForLight(local);
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

// accumulated = w * warped previous + (1 - w) * current where valid, current elsewhere; with
// `squared` the weights squared: the variance of that sum of independent estimates.
void accumulate(const FeatureMap& previous, const float* motion, const float* valid, FeatureMap& current,
                bool squared = false) {
    FeatureMap warped(current.height(), current.width(), 1);
    warpBilinear(previous, motion, warped);
    const float w = kLightHistoryWeight, rest = 1.0f - kLightHistoryWeight;
    const float old = squared ? w * w : w, fresh = squared ? rest * rest : rest;
    const std::size_t pixels = std::size_t(current.height()) * std::size_t(current.width());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(pixels); ++p) {
        if (valid[p] > 0.5f) current.data()[p] = old * warped.data()[p] + fresh * current.data()[p];
    }
}

}  // namespace

void blurForLight(FeatureMap& map) {
    for (int pass = 0; pass < kBoxPasses; ++pass) {
        boxRows(map, kLightBoxRadius);
        boxColumns(map, kLightBoxRadius);
    }
}

void restoreLight(const FeatureMap& noisy, const float* motion, const float* valid, bool useHistory,
                  LightHistory& history, float* radiance) {
    const int height = noisy.height(), width = noisy.width();
    FeatureMap input = luminanceMap(noisy.data(), height, width);
    FeatureMap variance = blurredVariance(input);
    blurForLight(input);
    FeatureMap output = luminanceMap(radiance, height, width);
    blurForLight(output);
    const bool continues = useHistory && history.input.height() == height && history.input.width() == width;
    if (continues) {
        accumulate(history.input, motion, valid, input);
        accumulate(history.output, motion, valid, output);
        accumulate(history.inputVariance, motion, valid, variance, true);
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
    history.input = std::move(input);
    history.output = std::move(output);
    history.inputVariance = std::move(variance);
}

}  // namespace affinity
