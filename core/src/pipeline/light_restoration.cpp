#include "pipeline/light_restoration.h"

#include <algorithm>
#include <cstddef>
#include <utility>
#include <vector>

#include "kernels/bilinear_warp.h"
#include "kernels/luminance.h"

namespace affinity {
namespace {

constexpr int kBoxPasses = 3;
constexpr int kColumnBlock = 64;  // columns per work item of the vertical pass
// The local mean a pixel's noise is measured against: one box pass of this radius per axis.
constexpr int kLocalMeanRadius = 2;

// Each output pixel the mean of the inputs within `radius` along the axis that lie inside the
// image, from running sums in double (adding and taking away values does not drift), one sum per
// lane: a block of kRowBlock rows, or of kColumnBlock columns, moves along together, so that the
// sums' additions do not wait on one another and every access runs along a row.
constexpr int kRowBlock = 8;

// 1 / (pixels inside the window at i), n pixels along the axis.
double inverseCount(int i, int n, int radius) {
    return 1.0 / double(std::min(n - 1, i + radius) - std::max(0, i - radius) + 1);
}

// `result` (the same size as `map`) gets map's rows boxed.
void boxRows(const FeatureMap& map, int radius, FeatureMap& result) {
    const int width = map.width(), height = map.height();
    const int blocks = (height + kRowBlock - 1) / kRowBlock;
#pragma omp parallel for schedule(static)
    for (int block = 0; block < blocks; ++block) {
        const int first = block * kRowBlock, count = std::min(height, first + kRowBlock) - first;
        const float* in[kRowBlock];
        float* out[kRowBlock];
        for (int k = 0; k < kRowBlock; ++k) {
            const int y = first + std::min(k, count - 1);  // a short last block repeats its last row
            in[k] = map.pixel(y, 0);
            out[k] = result.pixel(y, 0);
        }
        double sums[kRowBlock] = {};
        for (int x = 0; x <= std::min(radius, width - 1); ++x)
            for (int k = 0; k < kRowBlock; ++k) sums[k] += in[k][x];
        for (int x = 0; x < width; ++x) {
            const double inverse = inverseCount(x, width, radius);
            for (int k = 0; k < kRowBlock; ++k) out[k][x] = float(sums[k] * inverse);
            if (x + radius + 1 < width)
                for (int k = 0; k < kRowBlock; ++k) sums[k] += in[k][x + radius + 1];
            if (x - radius >= 0)
                for (int k = 0; k < kRowBlock; ++k) sums[k] -= in[k][x - radius];
        }
    }
}

// The same along the columns.
void boxColumns(const FeatureMap& map, int radius, FeatureMap& result) {
    const int width = map.width(), height = map.height();
    const int blocks = (width + kColumnBlock - 1) / kColumnBlock;
#pragma omp parallel
    {
        std::vector<double> sums(static_cast<std::size_t>(kColumnBlock));
#pragma omp for schedule(static)
        for (int block = 0; block < blocks; ++block) {
            const int first = block * kColumnBlock, count = std::min(width, first + kColumnBlock) - first;
            std::fill(sums.begin(), sums.end(), 0.0);
            for (int y = 0; y <= std::min(radius, height - 1); ++y) {
                const float* row = map.pixel(y, first);
                for (int i = 0; i < count; ++i) sums[std::size_t(i)] += row[i];
            }
            for (int y = 0; y < height; ++y) {
                const double inverse = inverseCount(y, height, radius);
                float* out = result.pixel(y, first);
                for (int i = 0; i < count; ++i) out[i] = float(sums[std::size_t(i)] * inverse);
                if (y + radius + 1 < height) {
                    const float* entering = map.pixel(y + radius + 1, first);
                    for (int i = 0; i < count; ++i) sums[std::size_t(i)] += entering[i];
                }
                if (y - radius >= 0) {
                    const float* leaving = map.pixel(y - radius, first);
                    for (int i = 0; i < count; ++i) sums[std::size_t(i)] -= leaving[i];
                }
            }
        }
    }
}

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
    boxRows(Y, kLocalMeanRadius, rows);
    boxColumns(rows, kLocalMeanRadius, local);
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

// accumulated = w * warped previous + (1 - w) * current where valid, current elsewhere; with
// `squared` the weights squared: the variance of that sum of independent estimates.
void accumulate(const FeatureMap& previous, const float* motion, const float* valid, FeatureMap& current,
                FeatureMapPool& pool, bool squared = false) {
    FeatureMap warped = pool.take(current.height(), current.width(), 1);
    warpBilinear(previous, motion, warped);
    const float w = kLightHistoryWeight, rest = 1.0f - kLightHistoryWeight;
    const float old = squared ? w * w : w, fresh = squared ? rest * rest : rest;
    const std::size_t pixels = std::size_t(current.height()) * std::size_t(current.width());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(pixels); ++p) {
        if (valid[p] > 0.5f) current.data()[p] = old * warped.data()[p] + fresh * current.data()[p];
    }
    pool.give(warped);
}

}  // namespace

void blurForLight(FeatureMap& map, FeatureMapPool& pool) {
    FeatureMap scratch = pool.take(map.height(), map.width(), 1);
    for (int pass = 0; pass < kBoxPasses; ++pass) {
        boxRows(map, kLightBoxRadius, scratch);
        boxColumns(scratch, kLightBoxRadius, map);
    }
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
        accumulate(history.input, motion, valid, input, pool);
        accumulate(history.output, motion, valid, output, pool);
        accumulate(history.inputVariance, motion, valid, variance, pool, true);
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
