#include "kernels/box_sums.h"

#include <algorithm>
#include <cstddef>
#include <vector>

namespace affinity {
namespace {

constexpr int kColumnBlock = 64;  // columns per work item of the vertical pass
// Running sums in double (adding and taking away values does not drift), one sum per lane: a
// block of kRowBlock rows, or of kColumnBlock columns, moves along together, so that the sums'
// additions do not wait on one another and every access runs along a row.
constexpr int kRowBlock = 8;

// 1 / (pixels inside the window at i), n pixels along the axis.
double inverseCount(int i, int n, int radius) {
    return 1.0 / double(std::min(n - 1, i + radius) - std::max(0, i - radius) + 1);
}

// `result` (the same size as `map`, not `map` itself) gets map's rows boxed.
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

}  // namespace

void boxRowsAndColumns(const FeatureMap& map, int radius, FeatureMap& scratch, FeatureMap& result) {
    boxRows(map, radius, scratch);
    boxColumns(scratch, radius, result);
}

}  // namespace affinity
