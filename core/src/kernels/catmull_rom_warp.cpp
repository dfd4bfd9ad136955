#include "kernels/catmull_rom_warp.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>

#include "affinity/error.h"
#include "kernels/bilinear_warp.h"
#include "kernels/warp_rows.h"

namespace affinity {
namespace {

constexpr int kLanes = 16;  // pixels whose taps are found together (this part vectorises)

// The 4x4 taps (clamped pixel coordinates) and Catmull-Rom weights of a block of pixels: tap i
// of a direction sits at floor(position) - 1 + i.
struct Taps {
    int x[4][kLanes], y[4][kLanes];
    float wx[4][kLanes], wy[4][kLanes];
};

// The motion's coordinate as a finite offset (NaN reads as no motion, as in the training
// framework's warp), then the position clamped to [0, size - 1].
inline float clampedPosition(int pixel, float motion, int size) {
    const float at = float(pixel) + (motion == motion ? motion : 0.0f);
    return at >= 0.0f ? (at <= float(size - 1) ? at : float(size - 1)) : 0.0f;
}

// Catmull-Rom weights of the taps at -1, 0, 1, 2 around a fraction t in [0, 1).
inline void weights(float t, float& w0, float& w1, float& w2, float& w3) {
    const float t2 = t * t, t3 = t2 * t;
    w0 = 0.5f * (-t3 + 2.0f * t2 - t);
    w1 = 0.5f * (3.0f * t3 - 5.0f * t2 + 2.0f);
    w2 = 0.5f * (-3.0f * t3 + 4.0f * t2 + t);
    w3 = 0.5f * (t3 - t2);
}

// Taps of pixels xBlock .. xBlock + count - 1 of row y.
void findTaps(const float* motion, int y, int xBlock, int count, int width, int height, Taps& taps) {
    const float* m = motion + 2 * (std::size_t(y) * std::size_t(width) + std::size_t(xBlock));
#pragma omp simd
    for (int l = 0; l < count; ++l) {
        const float px = clampedPosition(xBlock + l, m[2 * l], width);
        const float py = clampedPosition(y, m[2 * l + 1], height);
        const float floorX = std::floor(px), floorY = std::floor(py);
        weights(px - floorX, taps.wx[0][l], taps.wx[1][l], taps.wx[2][l], taps.wx[3][l]);
        weights(py - floorY, taps.wy[0][l], taps.wy[1][l], taps.wy[2][l], taps.wy[3][l]);
        const int x0 = int(floorX), y0 = int(floorY);
        for (int i = 0; i < 4; ++i) {
            taps.x[i][l] = std::clamp(x0 - 1 + i, 0, width - 1);
            taps.y[i][l] = std::clamp(y0 - 1 + i, 0, height - 1);
        }
    }
}

// Pixel l of the block: kChannels > 0 fixes the channel count at compile time (the sums then
// stay in registers), 0 reads it from the map and sums in `out`.
template <int kChannels>
void warpPixel(const FeatureMap& previous, const Taps& taps, int l, float* out) {
    const int channels = kChannels > 0 ? kChannels : previous.channels();
    float local[kChannels > 0 ? kChannels : 1];
    float* sum = kChannels > 0 ? local : out;
    for (int c = 0; c < channels; ++c) sum[c] = 0.0f;
    for (int j = 0; j < 4; ++j) {
        const float wy = taps.wy[j][l];
        for (int i = 0; i < 4; ++i) {
            const float w = wy * taps.wx[i][l];
            const float* p = previous.pixel(taps.y[j][l], taps.x[i][l]);
            for (int c = 0; c < channels; ++c) sum[c] += w * p[c];
        }
    }
    // The range of the four nearest taps (the bilinear footprint) bounds the result.
    const float* p00 = previous.pixel(taps.y[1][l], taps.x[1][l]);
    const float* p01 = previous.pixel(taps.y[1][l], taps.x[2][l]);
    const float* p10 = previous.pixel(taps.y[2][l], taps.x[1][l]);
    const float* p11 = previous.pixel(taps.y[2][l], taps.x[2][l]);
    for (int c = 0; c < channels; ++c) {
        const float low = std::min(std::min(p00[c], p01[c]), std::min(p10[c], p11[c]));
        const float high = std::max(std::max(p00[c], p01[c]), std::max(p10[c], p11[c]));
        out[c] = std::clamp(sum[c], low, high);
    }
}

template <int kChannels>
void warpRows(const FeatureMap& previous, const float* motion, int begin, int end, FeatureMap& output) {
    const int height = previous.height(), width = previous.width();
    warpRowsInBlocks<Taps, kLanes>(
        begin, end, width, output,
        [&](int y, int xBlock, int count, Taps& taps) { findTaps(motion, y, xBlock, count, width, height, taps); },
        [&](const Taps& taps, int l, float* out) { warpPixel<kChannels>(previous, taps, l, out); });
}

}  // namespace

void warpCatmullRom(const FeatureMap& previous, const float* motion, FeatureMap& output) {
    if (&output == &previous) throw Error("warpCatmullRom: the output must not be the input");
    output.resize(previous.height(), previous.width(), previous.channels());
    warpCatmullRomRows(previous, motion, 0, previous.height(), output);
}

void warpCatmullRomRows(const FeatureMap& previous, const float* motion, int begin, int end, FeatureMap& output) {
    checkWarpRows("warpCatmullRom", previous, begin, end, output);
    const int width = previous.width(), channels = previous.channels();
    if (begin == end || width == 0) return;
    if (motion == nullptr) throw Error("warpCatmullRom: no motion vectors");
    switch (channels) {
    case 3:
        return warpRows<3>(previous, motion, begin, end, output);
    case 6:
        return warpRows<6>(previous, motion, begin, end, output);
    case 9:
        return warpRows<9>(previous, motion, begin, end, output);
    case 12:
        return warpRows<12>(previous, motion, begin, end, output);
    default:
        return warpRows<0>(previous, motion, begin, end, output);
    }
}

}  // namespace affinity
