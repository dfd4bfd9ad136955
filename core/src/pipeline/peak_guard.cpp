#include "pipeline/peak_guard.h"

#include <algorithm>
#include <cmath>
#include <cstddef>

#include "kernels/luminance.h"

namespace affinity {
namespace {

// result(y, x) = the largest of map(y, x - radius .. x + radius) inside the image (1 channel).
void maxAlongRows(const FeatureMap& map, int radius, FeatureMap& result) {
    const int width = map.width();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < map.height(); ++y) {
        const float* row = map.pixel(y, 0);
        float* out = result.pixel(y, 0);
        for (int x = 0; x < width; ++x) {
            float m = row[x];
            for (int xx = std::max(0, x - radius); xx <= std::min(width - 1, x + radius); ++xx)
                m = std::max(m, row[xx]);
            out[x] = m;
        }
    }
}

// result(y, x) = the largest of map(y - radius .. y + radius, x) inside the image (1 channel).
void maxAlongColumns(const FeatureMap& map, int radius, FeatureMap& result) {
    const int height = map.height(), width = map.width();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y) {
        float* out = result.pixel(y, 0);
        std::copy(map.pixel(y, 0), map.pixel(y, 0) + width, out);
        for (int yy = std::max(0, y - radius); yy <= std::min(height - 1, y + radius); ++yy) {
            const float* row = map.pixel(yy, 0);
            for (int x = 0; x < width; ++x) out[x] = std::max(out[x], row[x]);
        }
    }
}

}  // namespace

float peakSupport(float luminance, float meanSquare, float emissiveShare, int spp) {
    if (emissiveShare > 0.0f) return luminance;
    return std::max(0.0f, luminance - std::sqrt(meanSquare / float(std::max(spp, 1))));
}

long guardPeaks(const FeatureMap& noisy, const FeatureMap& meanSquares, const FeatureMap& emissiveShare, int spp,
                float* radiance, FeatureMapPool& pool) {
    const int height = noisy.height(), width = noisy.width();
    const std::size_t pixels = std::size_t(height) * std::size_t(width);
    FeatureMap support = pool.take(height, width, 1), output = pool.take(height, width, 1);
    FeatureMap scratch = pool.take(height, width, 1), columns = pool.take(height, width, 1);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(pixels); ++p) {
        support.data()[p] = peakSupport(luminance(noisy.data() + std::size_t(p) * 3), meanSquares.data()[p],
                                        emissiveShare.data()[p], spp);
        output.data()[p] = luminance(radiance + std::size_t(p) * 3);
    }
    // The support's 3 x 3 maximum (into `support`). The ring kPeakRing pixels away is the rows
    // kPeakRing above and below, 2 kPeakRing + 1 wide (`scratch`), and the columns kPeakRing to
    // the left and right, 2 kPeakRing - 1 tall (`columns`).
    maxAlongRows(support, 1, scratch);
    maxAlongColumns(scratch, 1, support);
    maxAlongRows(output, kPeakRing, scratch);
    maxAlongColumns(output, kPeakRing - 1, columns);
    long capped = 0;
#pragma omp parallel for schedule(static) reduction(+ : capped)
    for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) {
            float ringMax = 0.0f;
            if (y >= kPeakRing) ringMax = std::max(ringMax, scratch.pixel(y - kPeakRing, x)[0]);
            if (y + kPeakRing < height) ringMax = std::max(ringMax, scratch.pixel(y + kPeakRing, x)[0]);
            if (x >= kPeakRing) ringMax = std::max(ringMax, columns.pixel(y, x - kPeakRing)[0]);
            if (x + kPeakRing < width) ringMax = std::max(ringMax, columns.pixel(y, x + kPeakRing)[0]);
            const float own = output.pixel(y, x)[0];
            const float cap = std::max(kPeakInputFactor * support.pixel(y, x)[0], kPeakNeighbourFactor * ringMax);
            if (!(own > cap)) continue;  // NaN-safe: a NaN stays as it was
            const float scale = cap / own;
            float* out = radiance + (std::size_t(y) * width + x) * 3;
            for (int c = 0; c < 3; ++c) out[c] *= scale;
            ++capped;
        }
    }
    pool.give(support);
    pool.give(output);
    pool.give(scratch);
    pool.give(columns);
    return capped;
}

}  // namespace affinity
