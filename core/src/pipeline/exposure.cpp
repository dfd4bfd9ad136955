#include "pipeline/exposure.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "affinity/features.h"

namespace affinity {

float exposureOf(const SampleBands& frame, int height) {
    const int width = frame.width, spp = frame.spp;
    const int binsX = (width + kExposureBin - 1) / kExposureBin, binsY = (height + kExposureBin - 1) / kExposureBin;
    std::vector<double> binMeans(std::size_t(binsX) * std::size_t(binsY), 0.0);
    // One square row per iteration: each square's sum is added in pixel order by one thread.
#pragma omp parallel for schedule(static)
    for (int by = 0; by < binsY; ++by) {
        std::vector<double> sums(std::size_t(binsX), 0.0);
        std::vector<int> counts(std::size_t(binsX), 0);
        const int lastRow = std::min(height, (by + 1) * kExposureBin);
        for (int y = by * kExposureBin; y < lastRow; y += kDepthScaleRowStep) {  // starts at a multiple of 4
            const float* row = frame.row(y);
            for (int x = 0; x < width; ++x) {
                const float* pixel = row + std::size_t(x) * std::size_t(spp) * kFeatureCount;
                double rgb[3] = {0.0, 0.0, 0.0};
                for (int s = 0; s < spp; ++s)
                    for (int c = 0; c < 6; ++c) {
                        const float r = pixel[std::size_t(s) * kFeatureCount + std::size_t(channel::kDiffuse + c)];
                        rgb[c % 3] += r >= 0.0f && r <= kMaxRadiance ? double(r) : 0.0;  // false for NaN
                    }
                sums[std::size_t(x / kExposureBin)] += (0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]) / spp;
                ++counts[std::size_t(x / kExposureBin)];
            }
        }
        for (int bx = 0; bx < binsX; ++bx)
            binMeans[std::size_t(by) * std::size_t(binsX) + std::size_t(bx)] =
                counts[std::size_t(bx)] > 0 ? sums[std::size_t(bx)] / counts[std::size_t(bx)] : 0.0;
    }
    double mean = 0.0;
    for (double m : binMeans) mean += m;
    mean /= double(binMeans.size());
    if (!(mean > 0.0) || !std::isfinite(mean)) return 0.0f;
    double logSum = 0.0;
    int lit = 0;
    for (double m : binMeans)
        if (m > kExposureDarkBin * mean) {
            logSum += std::log(m);
            ++lit;
        }
    return float(exposureForKey(std::exp(logSum / lit)));
}

}  // namespace affinity
