#include "pipeline/peak_guard.h"

#include <algorithm>
#include <cmath>
#include <cstddef>

#include "kernels/luminance.h"

namespace affinity {

float peakSupport(float luminance, float meanSquare, float emissiveShare, int spp) {
    if (emissiveShare > 0.0f) return luminance;
    return std::max(0.0f, luminance - std::sqrt(meanSquare / float(std::max(spp, 1))));
}

long guardPeaks(const FeatureMap& noisy, const FeatureMap& meanSquares, const FeatureMap& emissiveShare, int spp,
                float* radiance, FeatureMapPool& pool) {
    const int height = noisy.height(), width = noisy.width();
    const std::size_t pixels = std::size_t(height) * std::size_t(width);
    FeatureMap input = pool.take(height, width, 1), output = pool.take(height, width, 1);
    FeatureMap rowMax = pool.take(height, width, 1);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(pixels); ++p) {
        input.data()[p] = peakSupport(luminance(noisy.data() + std::size_t(p) * 3), meanSquares.data()[p],
                                      emissiveShare.data()[p], spp);
        output.data()[p] = luminance(radiance + std::size_t(p) * 3);
    }
    // The support's 3 x 3 maximum, along rows then columns.
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y) {
        const float* row = input.data() + std::size_t(y) * width;
        float* result = rowMax.data() + std::size_t(y) * width;
        for (int x = 0; x < width; ++x) {
            float m = row[x];
            if (x > 0) m = std::max(m, row[x - 1]);
            if (x + 1 < width) m = std::max(m, row[x + 1]);
            result[x] = m;
        }
    }
    long capped = 0;
#pragma omp parallel for schedule(static) reduction(+ : capped)
    for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) {
            const std::size_t p = std::size_t(y) * width + x;
            float inputMax = 0.0f, ringMax = 0.0f;
            for (int dy = -1; dy <= 1; ++dy)
                if (y + dy >= 0 && y + dy < height) inputMax = std::max(inputMax, rowMax.pixel(y + dy, x)[0]);
            for (int dy = -kPeakRing; dy <= kPeakRing; ++dy) {
                const int yy = y + dy;
                if (yy < 0 || yy >= height) continue;
                // The whole row at the ring's top and bottom, its two ends in between.
                const int step = (dy == -kPeakRing || dy == kPeakRing) ? 1 : 2 * kPeakRing;
                for (int dx = -kPeakRing; dx <= kPeakRing; dx += step) {
                    const int xx = x + dx;
                    if (xx >= 0 && xx < width) ringMax = std::max(ringMax, output.data()[std::size_t(yy) * width + xx]);
                }
            }
            const float own = output.data()[p];
            const float cap = std::max(kPeakInputFactor * inputMax, kPeakNeighbourFactor * ringMax);
            if (!(own > cap)) continue;  // NaN-safe: a NaN stays as it was
            const float scale = cap / own;
            float* out = radiance + p * 3;
            for (int c = 0; c < 3; ++c) out[c] *= scale;
            ++capped;
        }
    }
    pool.give(input);
    pool.give(output);
    pool.give(rowMax);
    return capped;
}

}  // namespace affinity
