#include "kernels/bilinear_warp.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>

#include "affinity/error.h"
#include "kernels/warp_rows.h"

namespace affinity {
namespace {

constexpr int kLanes = 8;  // pixels whose taps are found together (this part vectorises)

// The four taps (clamped pixel coordinates) and bilinear fractions of a block of pixels.
struct Taps {
    int left[kLanes], right[kLanes], top[kLanes], bottom[kLanes];
    float fx[kLanes], fy[kLanes];
};

// Taps of pixels xBlock .. xBlock + count - 1 of row y.
void findTaps(const float* motion, int y, int xBlock, int count, int width, int height, Taps& taps) {
    const float* m = motion + 2 * (std::size_t(y) * std::size_t(width) + std::size_t(xBlock));
#pragma omp simd
    for (int l = 0; l < count; ++l) {
        // NaN motion reads as no motion (as in the Catmull-Rom warp and the training
        // framework's). Clamping the position to one pixel beyond the border first keeps the
        // integer conversion defined for infinite or huge motion and changes nothing: both
        // taps clamp to the border pixel there anyway.
        const float mx = m[2 * l], my = m[2 * l + 1];
        float sx = float(xBlock + l) + (mx == mx ? mx : 0.0f), sy = float(y) + (my == my ? my : 0.0f);
        sx = sx >= -1.0f ? (sx <= float(width) ? sx : float(width)) : -1.0f;
        sy = sy >= -1.0f ? (sy <= float(height) ? sy : float(height)) : -1.0f;
        const float floorX = std::floor(sx), floorY = std::floor(sy);
        taps.fx[l] = sx - floorX;
        taps.fy[l] = sy - floorY;
        const int x0 = int(floorX), y0 = int(floorY);
        taps.left[l] = std::clamp(x0, 0, width - 1);
        taps.right[l] = std::clamp(x0 + 1, 0, width - 1);
        taps.top[l] = std::clamp(y0, 0, height - 1);
        taps.bottom[l] = std::clamp(y0 + 1, 0, height - 1);
    }
}

// One map's pixel l of the block: kChannels > 0 fixes the channel count at compile time (the
// blend then compiles to a few whole-vector operations), 0 reads it from the map.
template <int kChannels>
void blendPixel(const FeatureMap& previous, const Taps& taps, int l, float* out) {
    const int channels = kChannels > 0 ? kChannels : previous.channels();
    const float* p00 = previous.pixel(taps.top[l], taps.left[l]);
    const float* p01 = previous.pixel(taps.top[l], taps.right[l]);
    const float* p10 = previous.pixel(taps.bottom[l], taps.left[l]);
    const float* p11 = previous.pixel(taps.bottom[l], taps.right[l]);
    const float fx = taps.fx[l], fy = taps.fy[l];
    const float w00 = (1 - fx) * (1 - fy), w01 = fx * (1 - fy);
    const float w10 = (1 - fx) * fy, w11 = fx * fy;
#pragma omp simd
    for (int c = 0; c < channels; ++c) out[c] = w00 * p00[c] + w01 * p01[c] + w10 * p10[c] + w11 * p11[c];
}

template <int kChannels>
void warpRows(const FeatureMap& previous, const float* motion, int begin, int end, FeatureMap& output) {
    const int height = previous.height(), width = previous.width();
    warpRowsInBlocks<Taps, kLanes>(
        begin, end, width, output,
        [&](int y, int xBlock, int count, Taps& taps) { findTaps(motion, y, xBlock, count, width, height, taps); },
        [&](const Taps& taps, int l, float* out) { blendPixel<kChannels>(previous, taps, l, out); });
}

// The channel counts of today's maps with a constant count: embedding 16 or 32, features 8,
// and 3, the RGB images of the metrics' warps.
void dispatch(const FeatureMap& previous, const float* motion, int begin, int end, FeatureMap& output) {
    switch (previous.channels()) {
    case 3:
        return warpRows<3>(previous, motion, begin, end, output);
    case 8:
        return warpRows<8>(previous, motion, begin, end, output);
    case 16:
        return warpRows<16>(previous, motion, begin, end, output);
    case 32:
        return warpRows<32>(previous, motion, begin, end, output);
    default:
        return warpRows<0>(previous, motion, begin, end, output);
    }
}

}  // namespace

void checkWarpRows(const char* warp, const FeatureMap& previous, int begin, int end, const FeatureMap& output) {
    if (&output == &previous) throw Error(std::string(warp) + ": the output must not be the input");
    const int height = previous.height(), width = previous.width(), channels = previous.channels();
    if (begin < 0 || end > height || begin > end)
        throw Error(std::string(warp) + ": rows " + std::to_string(begin) + ".." + std::to_string(end) +
                    " are not inside an image of " + std::to_string(height) + " rows");
    if (output.width() != width || output.channels() != channels || output.height() < std::min(height, end - begin))
        throw Error(std::string(warp) + ": the output is " + std::to_string(output.height()) + " x " +
                    std::to_string(output.width()) + " x " + std::to_string(output.channels()) +
                    ", too small for rows " + std::to_string(begin) + ".." + std::to_string(end) + " of a " +
                    std::to_string(width) + "-wide " + std::to_string(channels) + "-channel map");
}

void warpBilinear(const FeatureMap& previous, const float* motion, FeatureMap& output) {
    if (&output == &previous) throw Error("warpBilinear: the output must not be the input");
    output.resize(previous.height(), previous.width(), previous.channels());
    warpBilinearRows(previous, motion, 0, previous.height(), output);
}

void warpBilinearRows(const FeatureMap& previous, const float* motion, int begin, int end, FeatureMap& output) {
    checkWarpRows("warpBilinear", previous, begin, end, output);
    if (begin == end || previous.width() == 0) return;
    if (motion == nullptr) throw Error("warpBilinear: no motion vectors");
    dispatch(previous, motion, begin, end, output);
}

}  // namespace affinity
