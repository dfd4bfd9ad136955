#include "bilinear_warp.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>

#include "affinity/error.h"

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
        // Clamping the position to one pixel beyond the border first keeps the integer
        // conversion defined for any motion (even NaN or huge values) and changes
        // nothing: both taps clamp to the border pixel there anyway.
        float sx = float(xBlock + l) + m[2 * l], sy = float(y) + m[2 * l + 1];
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

// Rows [begin, end) of `first` (and of `second` where not null), checked by the caller.
template <int kFirst, int kSecond>
void warpRows(const FeatureMap& first, const FeatureMap* second, const float* motion, int begin, int end,
              FeatureMap& firstOutput, FeatureMap* secondOutput) {
    const int height = first.height(), width = first.width();
#pragma omp parallel for schedule(static)
    for (int y = begin; y < end; ++y) {
        float* firstRow = firstOutput.pixel(y % firstOutput.height(), 0);
        float* secondRow = second ? secondOutput->pixel(y % secondOutput->height(), 0) : nullptr;
        for (int xBlock = 0; xBlock < width; xBlock += kLanes) {
            const int count = std::min(kLanes, width - xBlock);
            Taps taps;
            findTaps(motion, y, xBlock, count, width, height, taps);
            for (int l = 0; l < count; ++l) {
                const std::size_t x = std::size_t(xBlock + l);
                blendPixel<kFirst>(first, taps, l, firstRow + x * std::size_t(first.channels()));
                if (second) blendPixel<kSecond>(*second, taps, l, secondRow + x * std::size_t(second->channels()));
            }
        }
    }
}

// The channel counts of today's maps with a constant count: embedding 16 or 32, features 8,
// signal 3 (RGB) and its demodulated forms 6, 9 and 12 (filter_signal.h).
template <int kFirst>
void warpRowsWithSecond(const FeatureMap& first, const FeatureMap& second, const float* motion, int begin, int end,
                        FeatureMap& firstOutput, FeatureMap& secondOutput) {
    switch (second.channels()) {
        case 3: return warpRows<kFirst, 3>(first, &second, motion, begin, end, firstOutput, &secondOutput);
        case 6: return warpRows<kFirst, 6>(first, &second, motion, begin, end, firstOutput, &secondOutput);
        case 9: return warpRows<kFirst, 9>(first, &second, motion, begin, end, firstOutput, &secondOutput);
        case 12: return warpRows<kFirst, 12>(first, &second, motion, begin, end, firstOutput, &secondOutput);
        default: return warpRows<kFirst, 0>(first, &second, motion, begin, end, firstOutput, &secondOutput);
    }
}

void dispatch(const FeatureMap& first, const FeatureMap* second, const float* motion, int begin, int end,
              FeatureMap& firstOutput, FeatureMap* secondOutput) {
    if (second) {
        switch (first.channels()) {
            case 8: return warpRowsWithSecond<8>(first, *second, motion, begin, end, firstOutput, *secondOutput);
            case 16: return warpRowsWithSecond<16>(first, *second, motion, begin, end, firstOutput, *secondOutput);
            case 32: return warpRowsWithSecond<32>(first, *second, motion, begin, end, firstOutput, *secondOutput);
            default: return warpRows<0, 0>(first, second, motion, begin, end, firstOutput, secondOutput);
        }
    }
    switch (first.channels()) {
        case 3: return warpRows<3, 0>(first, nullptr, motion, begin, end, firstOutput, nullptr);
        case 8: return warpRows<8, 0>(first, nullptr, motion, begin, end, firstOutput, nullptr);
        case 16: return warpRows<16, 0>(first, nullptr, motion, begin, end, firstOutput, nullptr);
        case 32: return warpRows<32, 0>(first, nullptr, motion, begin, end, firstOutput, nullptr);
        default: return warpRows<0, 0>(first, nullptr, motion, begin, end, firstOutput, nullptr);
    }
}

// Rows [begin, end) of `previous` must be inside it, and `output` must hold them.
void checkRows(const FeatureMap& previous, int begin, int end, const FeatureMap& output) {
    if (&output == &previous) throw Error("warpBilinear: the output must not be the input");
    const int height = previous.height(), width = previous.width(), channels = previous.channels();
    if (begin < 0 || end > height || begin > end)
        throw Error("warpBilinear: rows " + std::to_string(begin) + ".." + std::to_string(end) +
                    " are not inside an image of " + std::to_string(height) + " rows");
    if (output.width() != width || output.channels() != channels || output.height() < std::min(height, end - begin))
        throw Error("warpBilinear: the output is " + std::to_string(output.height()) + " x " +
                    std::to_string(output.width()) + " x " + std::to_string(output.channels()) +
                    ", too small for rows " + std::to_string(begin) + ".." + std::to_string(end) + " of a " +
                    std::to_string(width) + "-wide " + std::to_string(channels) + "-channel map");
}

}  // namespace

void warpBilinear(const FeatureMap& previous, const float* motion, FeatureMap& output) {
    if (&output == &previous) throw Error("warpBilinear: the output must not be the input");
    output.resize(previous.height(), previous.width(), previous.channels());
    warpBilinearRows(previous, motion, 0, previous.height(), output);
}

void warpBilinearRows(const FeatureMap& previous, const float* motion, int begin, int end, FeatureMap& output) {
    checkRows(previous, begin, end, output);
    if (begin == end || previous.width() == 0) return;
    if (motion == nullptr) throw Error("warpBilinear: no motion vectors");
    dispatch(previous, nullptr, motion, begin, end, output, nullptr);
}

void warpBilinear(const FeatureMap& first, const FeatureMap& second, const float* motion, FeatureMap& firstOutput,
                  FeatureMap& secondOutput) {
    if (&firstOutput == &second || &secondOutput == &first) throw Error("warpBilinear: an output must not be an input");
    firstOutput.resize(first.height(), first.width(), first.channels());
    secondOutput.resize(second.height(), second.width(), second.channels());
    warpBilinearRows(first, second, motion, 0, first.height(), firstOutput, secondOutput);
}

void warpBilinearRows(const FeatureMap& first, const FeatureMap& second, const float* motion, int begin, int end,
                      FeatureMap& firstOutput, FeatureMap& secondOutput) {
    if (second.height() != first.height() || second.width() != first.width())
        throw Error("warpBilinear: the maps warped together are " + std::to_string(first.height()) + " x " +
                    std::to_string(first.width()) + " and " + std::to_string(second.height()) + " x " +
                    std::to_string(second.width()) + "; they must be the same size");
    if (&firstOutput == &secondOutput) throw Error("warpBilinear: the two outputs must differ");
    if (&firstOutput == &second || &secondOutput == &first) throw Error("warpBilinear: an output must not be an input");
    checkRows(first, begin, end, firstOutput);
    checkRows(second, begin, end, secondOutput);
    if (begin == end || first.width() == 0) return;
    if (motion == nullptr) throw Error("warpBilinear: no motion vectors");
    dispatch(first, &second, motion, begin, end, firstOutput, &secondOutput);
}

}  // namespace affinity
