#include "pipeline/input_fallback.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <utility>

#include "kernels/box_sums.h"
#include "kernels/luminance.h"
#include "pipeline/motion_blend.h"

namespace affinity {
namespace {

// `map` boxed over the window, in place.
void boxWindow(FeatureMap& map, int radius, FeatureMapPool& pool) {
    FeatureMap rows = pool.take(map.height(), map.width(), 1);
    boxRowsAndColumns(map, radius, rows, map);
    pool.give(rows);
}

// radiance += share * (noisy - radiance), the share max(0, D - k V) / D (at most 1) from the
// windowed departure D and the accumulated noise V.
void moveTowardInput(const FeatureMap& noisy, const FeatureMap& departure, const FeatureMap& variance,
                     float* radiance) {
    const std::size_t pixels = std::size_t(noisy.height()) * std::size_t(noisy.width());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(pixels); ++p) {
        const float d = departure.data()[p];
        if (!(d > 0.0f)) continue;
        const float share = std::clamp((d - kFallbackNoiseFactor * variance.data()[p]) / d, 0.0f, 1.0f);
        if (share <= 0.0f) continue;  // the output as it was, bit for bit
        float* out = radiance + std::size_t(p) * 3;
        const float* in = noisy.data() + std::size_t(p) * 3;
        for (int c = 0; c < 3; ++c) out[c] += share * (in[c] - out[c]);
    }
}

}  // namespace

int fallbackRadius(int spp) {
    const double side = std::sqrt(double(kFallbackWindowSamples) / double(std::max(spp, 1)));
    return std::max(1, int(std::lround((side - 1.0) / 2.0)));
}

void fallBackToInput(const FeatureMap& noisy, const FeatureMap& meanSquares, int spp, const float* motion,
                     const float* valid, bool useHistory, FeatureMap& noiseHistory, float* radiance,
                     FeatureMapPool& pool) {
    const int height = noisy.height(), width = noisy.width();
    const std::size_t pixels = std::size_t(height) * std::size_t(width);
    FeatureMap departure = pool.take(height, width, 1), mean = pool.take(height, width, 1);
    FeatureMap variance = pool.take(height, width, 1);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(pixels); ++p) {
        const float input = luminance(noisy.data() + std::size_t(p) * 3);
        const float difference = input - luminance(radiance + std::size_t(p) * 3);
        departure.data()[p] = difference * difference;
        mean.data()[p] = input;
        variance.data()[p] = meanSquares.data()[p];
    }
    const int radius = fallbackRadius(spp);
    boxWindow(mean, radius, pool);
    boxWindow(variance, radius, pool);  // the window's mean square, then its variance of a pixel's mean:
    const float perPixel = 1.0f / float(std::max(spp, 1));
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(pixels); ++p) {
        const float m = mean.data()[p];
        variance.data()[p] = std::max(0.0f, variance.data()[p] - m * m) * perPixel;
    }
    pool.give(mean);
    // A frame without history only measures its noise: in one frame a window's few samples of
    // heavy-tailed light often hold none of its rare bright ones, and read as noiseless.
    if (useHistory && noiseHistory.height() == height && noiseHistory.width() == width) {
        boxWindow(departure, radius, pool);
        blendAlongMotion(noiseHistory, motion, valid, kFallbackHistoryWeight, variance, pool);
        moveTowardInput(noisy, departure, variance, radiance);
    }
    pool.give(departure);
    if (noiseHistory.height() > 0) pool.give(noiseHistory);  // read: its memory serves the next frame
    noiseHistory = std::move(variance);
}

}  // namespace affinity
