#pragma once
// The affinity filter's inner loops (affinity_filter.cpp): one output row in strips of
// kStripVectors vectors of L lanes, written once over the lane count. The AVX2 build
// instantiates them with L = 8 (affinity_filter.cpp), the AVX-512 one with L = 16
// (affinity_filter_avx512.cpp, chosen at run time). Every lane goes through the same
// operations, so both give the same bits.
#include <algorithm>
#include <cstddef>
#include <cstring>
#include <limits>
#include <utility>

#include "kernels/fast_exp.h"
#include "kernels/luminance.h"

namespace affinity {

// Everything one output row needs: planar rows of the centre and of each neighbour row.
struct FilterRowInputs {
    int width;
    int features;
    std::size_t stride;        // of the spatial rows
    const float* centre;       // features, signal, a, c (and b when temporal) at row y
    const float* const* taps;  // per tap row j = 0..T-1: features and signal, or null outside
    int tapSize;
    int dilation;
    std::size_t temporalStride;        // of the temporal rows
    const float* const* temporalRows;  // rows y-1, y, y+1: warped features, output, validity
    float guardRatio;                  // the bright-history guard (affinity_filter.h); 0: none
    float guardFloor;
};

using FilterRowFunction = void (*)(const FilterRowInputs&, float*);

// Inputs wider than a row: the widest strip reads this far past the last pixel.
inline constexpr int kStripVectors = 8;
inline constexpr int kMaxStripPixels = kStripVectors * 16;

#if AFFINITY_HAVE_AVX512_KERNEL
// The row function for these inputs with 16 lanes (call only where cpuHasAvx512()).
FilterRowFunction filterRowFunctionAvx512(bool temporal, int features);
#endif

// Internal linkage: each instruction set's translation unit keeps its own copies.
namespace {

constexpr float kEpsilon = 1e-8f;
// Feature counts with a kernel specialised at compile time (feature loop fully unrolled);
// others use the generic one.
constexpr int kMaxSpecialisedFeatures = 16;

template <int L>
VecF<L> loadLanes(const float* p) {
    VecF<L> v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

template <int L>
VecI<L> laneIndices() {
    VecI<L> lanes;
    for (int l = 0; l < L; ++l) lanes[l] = l;
    return lanes;
}

// Sum of squared feature differences between the centre pixels and the pixels at `neighbour`.
// Four partial sums keep the dependency chain short; the pointers advance plane by plane so the
// loop needs two address registers rather than one per feature plane.
template <int L, int kFeatures>
VecF<L> squaredDistance(const float* centre, const float* neighbour, std::size_t centreStride,
                        std::size_t neighbourStride, int features) {
    VecF<L> partial[4] = {};
    const int count = kFeatures > 0 ? kFeatures : features;
    for (int c = 0; c < count; ++c) {
        const VecF<L> d = loadLanes<L>(centre) - loadLanes<L>(neighbour);
        partial[c % 4] += d * d;
        centre += centreStride;
        neighbour += neighbourStride;
    }
    return (partial[0] + partial[1]) + (partial[2] + partial[3]);
}

// Rec. 709 luminance (kernels/luminance.h) of the L pixels whose R, G and B planes start at `rgb`,
// `stride` apart.
template <int L>
VecF<L> luminanceLanes(const float* rgb, std::size_t stride) {
    return kLumaR * loadLanes<L>(rgb) + kLumaG * loadLanes<L>(rgb + stride) + kLumaB * loadLanes<L>(rgb + 2 * stride);
}

// The weighted sums of one vector of L pixels.
template <int L, int kChannels>
struct VectorSums {
    VecF<L> value[kChannels], weight;
};

// Adds one tap, the neighbour at the same offset for every lane: `neighbour` points at the
// features of the first lane's neighbour, `column` is that neighbour's image column, `signal`
// its kChannels filtered values; `scale` (null for none: the spatial taps) multiplies each
// weight: what a temporal tap may give (its validity, and the bright-history guard).
// kCheckColumns: some neighbours may lie outside the image horizontally and are masked out.
template <int L, int kFeatures, int kChannels, bool kCheckColumns>
void addTap(VectorSums<L, kChannels>& sums, VecF<L> negativeBandwidthSquared, const float* centre,
            std::size_t centreStride, const float* neighbour, std::size_t neighbourStride, const float* signal,
            const VecF<L>* scale, int features, int column, int width) {
    const VecF<L> distance = squaredDistance<L, kFeatures>(centre, neighbour, centreStride, neighbourStride, features);
    VecF<L> weight = fastExpNonPositiveLanes<L>(negativeBandwidthSquared * distance);
    if (scale != nullptr) weight *= *scale;
    if constexpr (kCheckColumns) {
        const VecI<L> columns = laneIndices<L>() + column;
        weight = ((columns >= 0) & (columns < width)) ? weight : VecF<L>{};
    }
    for (int c = 0; c < kChannels; ++c) sums.value[c] += weight * loadLanes<L>(signal + c * neighbourStride);
    sums.weight += weight;
}

// Filters the (kStripVectors * L) pixels starting at column x of one row, one vector of L
// pixels at a time through every tap: the vector's sums and centre features stay in registers,
// and the processor overlaps the exp chains of consecutive taps, which are independent. Each
// lane adds its taps in the same order as any other tiling would. Vectors wholly past the
// image's right edge are skipped; lanes past it compute on zero padding and are not stored.
template <int L, int kFeatures, int kChannels, bool kCheckColumns, bool kTemporal>
void filterStrip(const FilterRowInputs& in, int x, float* output) {
    const int features = kFeatures > 0 ? kFeatures : in.features;
    const std::size_t stride = in.stride;
    const int radius = in.tapSize / 2;
    const int count = std::min((kStripVectors * L), in.width - x);

    for (int v = 0; v * L < count; ++v) {
        const int at = x + v * L;
        const float* centre = in.centre + at;
        const float* centreSignal = centre + features * stride;
        const VecF<L> a = loadLanes<L>(centre + (features + kChannels) * stride);
        const VecF<L> negativeBandwidthSquared = -(a * a);
        const VecF<L> centreWeight = loadLanes<L>(centre + (features + kChannels + 1) * stride);
        VectorSums<L, kChannels> sums;
        for (int k = 0; k < kChannels; ++k) sums.value[k] = centreWeight * loadLanes<L>(centreSignal + k * stride);
        sums.weight = centreWeight;

        for (int j = 0; j < in.tapSize; ++j) {
            const float* tapRow = in.taps[j];
            if (tapRow == nullptr) continue;
            for (int i = -radius; i <= radius; ++i) {
                if (i == 0 && j == radius) continue;  // the centre, weighted by c above
                const int column = at + i * in.dilation;
                const float* neighbour = tapRow + column;
                addTap<L, kFeatures, kChannels, kCheckColumns>(sums, negativeBandwidthSquared, centre, stride,
                                                               neighbour, stride, neighbour + features * stride,
                                                               nullptr, features, column, in.width);
            }
        }

        if constexpr (kTemporal) {
            const std::size_t temporalStride = in.temporalStride;
            const VecF<L> b = loadLanes<L>(centre + (features + kChannels + 2) * stride);
            const VecF<L> negativeTemporalSquared = -(b * b);
            // The brightest warped output a tap may have (the guard off: every value passes).
            const VecF<L> brightest = in.guardRatio > 0.0f
                                          ? in.guardRatio * (luminanceLanes<L>(centreSignal, stride) + in.guardFloor)
                                          : VecF<L>{} + std::numeric_limits<float>::infinity();
            for (int j = 0; j < 3; ++j) {
                const float* tapRow = in.temporalRows[j];
                if (tapRow == nullptr) continue;
                for (int i = -1; i <= 1; ++i) {
                    const int column = at + i;
                    const float* neighbour = tapRow + column;
                    const float* warpedOutput = neighbour + features * temporalStride;
                    const VecF<L> validity = loadLanes<L>(warpedOutput + kChannels * temporalStride);
                    const VecF<L> scale =
                        luminanceLanes<L>(warpedOutput, temporalStride) <= brightest ? validity : VecF<L>{};
                    addTap<L, kFeatures, kChannels, kCheckColumns>(sums, negativeTemporalSquared, centre, stride,
                                                                   neighbour, temporalStride, warpedOutput, &scale,
                                                                   features, column, in.width);
                }
            }
        }

        const VecF<L> normaliser = sums.weight + kEpsilon;
        VecF<L> result[kChannels];
        for (int c = 0; c < kChannels; ++c) result[c] = sums.value[c] / normaliser;
        const int lanes = std::min(L, count - v * L);
        float* out = output + kChannels * std::size_t(v * L);
        for (int l = 0; l < lanes; ++l)
            for (int c = 0; c < kChannels; ++c) out[kChannels * l + c] = result[c][l];
    }
}

template <int L, int kFeatures, int kChannels, bool kTemporal>
void filterRow(const FilterRowInputs& in, float* output) {
    // Strips whose taps all lie inside the image need no column test.
    const int margin = std::max((in.tapSize / 2) * in.dilation, kTemporal ? 1 : 0);
    for (int x = 0; x < in.width; x += (kStripVectors * L)) {
        const bool interior = x - margin >= 0 && x + (kStripVectors * L) - 1 + margin < in.width;
        float* out = output + kChannels * std::size_t(x);
        if (interior) {
            filterStrip<L, kFeatures, kChannels, false, kTemporal>(in, x, out);
        } else {
            filterStrip<L, kFeatures, kChannels, true, kTemporal>(in, x, out);
        }
    }
}

template <int L, int kChannels, bool kTemporal, int... kCounts>
FilterRowFunction selectRowFunction(int features, std::integer_sequence<int, kCounts...>) {
    FilterRowFunction chosen = &filterRow<L, 0, kChannels, kTemporal>;
    ((features == kCounts + 1 ? (chosen = &filterRow<L, kCounts + 1, kChannels, kTemporal>, 0) : 0), ...);
    return chosen;
}

// The row function for `features` features and the 3 channels of the signal (RGB radiance).
template <int L>
FilterRowFunction filterRowFunction(bool temporal, int features) {
    constexpr auto counts = std::make_integer_sequence<int, kMaxSpecialisedFeatures>{};
    return temporal ? selectRowFunction<L, 3, true>(features, counts)
                    : selectRowFunction<L, 3, false>(features, counts);
}

}  // namespace
}  // namespace affinity
