#pragma once
// What the Winograd forms (winograd_conv.h, coarse_winograd.h) share besides the vector loads
// of winograd_transforms.h: fetching a tile's input patch.
#include <algorithm>
#include <cstddef>

#include "kernels/conv_kernel.h"

namespace affinity::winograd {

// The Patch x Patch input patch whose top-left pixel is (y0, x0) in a height x width image read
// from `source` (an upsampled source at (y / 2, x / 2)): rows[i] points at its row i, whose
// pixels are the returned stride apart. Straight from the image where the patch lies inside it,
// else copied into `patch` (Patch * Patch * channels floats) with zeros for the padding.
template <int Patch>
std::size_t patchRows(const ConvSource& source, int height, int width, int y0, int x0, float* patch,
                      const float* (&rows)[Patch]) {
    const std::size_t channels = std::size_t(source.channels);
    if (!source.upsampled && y0 >= 0 && y0 + Patch <= height && x0 >= 0 && x0 + Patch <= width) {
        for (int i = 0; i < Patch; ++i)
            rows[i] = source.data + (std::size_t(y0 + i) * width + std::size_t(x0)) * channels;
        return channels;
    }
    const std::size_t sourceWidth = source.upsampled ? std::size_t(width + 1) / 2 : std::size_t(width);
    for (int i = 0; i < Patch; ++i) {
        rows[i] = patch + std::size_t(i) * Patch * channels;
        for (int j = 0; j < Patch; ++j) {
            float* dst = patch + std::size_t(i * Patch + j) * channels;
            const int y = y0 + i, x = x0 + j;
            if (y < 0 || y >= height || x < 0 || x >= width) {
                std::fill(dst, dst + channels, 0.0f);
                continue;
            }
            const int sy = source.upsampled ? y / 2 : y, sx = source.upsampled ? x / 2 : x;
            const float* pixel = source.data + (std::size_t(sy) * sourceWidth + std::size_t(sx)) * channels;
            std::copy(pixel, pixel + channels, dst);
        }
    }
    return channels;
}

}  // namespace affinity::winograd
