#pragma once
// The row loop every warp shares (bilinear_warp.h, catmull_rom_warp.h): rows [begin, end) of
// an image `width` pixels wide, in blocks of kLanes pixels whose taps are found together (that
// part vectorises), then each pixel of the block resampled on its own.
#include <algorithm>
#include <cstddef>

#include "kernels/feature_map.h"

namespace affinity {

// findTaps(y, xBlock, count, taps) fills the taps of pixels xBlock .. xBlock + count - 1 of row
// y; warpPixel(taps, l, out) writes pixel l of the block. `output` holds image row y at row
// y % output.height() (a ring, or the whole image).
template <class Taps, int kLanes, class FindTaps, class WarpPixel>
void warpRowsInBlocks(int begin, int end, int width, FeatureMap& output, FindTaps findTaps, WarpPixel warpPixel) {
    const std::size_t channels = std::size_t(output.channels());
#pragma omp parallel for schedule(static)
    for (int y = begin; y < end; ++y) {
        float* row = output.pixel(y % output.height(), 0);
        for (int xBlock = 0; xBlock < width; xBlock += kLanes) {
            const int count = std::min(kLanes, width - xBlock);
            Taps taps;
            findTaps(y, xBlock, count, taps);
            for (int l = 0; l < count; ++l) warpPixel(taps, l, row + std::size_t(xBlock + l) * channels);
        }
    }
}

}  // namespace affinity
