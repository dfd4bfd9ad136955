#include "kernels/affinity_filter.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include "affinity/error.h"
#include "kernels/affinity_strips.h"
#include "kernels/conv_kernel.h"

namespace affinity {
namespace {

constexpr int kLanes = 8;  // of the row transposes
// The filtered signal: RGB radiance (network/filter_signal.h).
constexpr int kSignalChannels = 3;

Vec8f load8(const float* p) {
    Vec8f v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

// Planar, zero-padded copies of image rows. The inputs are NHWC (a pixel's channels adjacent);
// the kernels want each channel's row contiguous so that eight neighbouring pixels are one
// vector load (indexing NHWC per channel makes the compiler gather, several times slower:
// docs/METHOD.md section 12). Each row is transposed once per thread into a ring of slots
// covering the rows a kernel reaches.
class PlanarRows {
public:
    // `pad` zero columns on the left, `pad + kMaxStripPixels` on the right (a strip starting near
    // the last pixel reads past it); `span` rows are held at once.
    PlanarRows(std::vector<const FeatureMap*> sources, int pad, int span)
        : sources_(std::move(sources)), width_(sources_.front()->width()), pad_(pad) {
        for (const FeatureMap* source : sources_) planes_ += source->channels();
        // Planes start on 64-byte boundaries relative to the slot.
        stride_ = (std::size_t(pad_) * 2 + width_ + kMaxStripPixels + 15) / 16 * 16;
        slots_ = std::max(1, std::min(span, sources_.front()->height()));
        slotRow_.assign(std::size_t(slots_), -1);
        storage_.assign(std::size_t(slots_) * planes_ * stride_, 0.0f);
    }

    std::size_t stride() const { return stride_; }

    // Pointer to column 0 of plane 0 of row y; plane k starts stride() * k floats later.
    const float* row(int y) {
        const std::size_t slot = std::size_t(y % slots_);
        float* base = storage_.data() + slot * planes_ * stride_ + pad_;
        if (slotRow_[slot] != y) {
            transpose(y, base);
            slotRow_[slot] = y;
        }
        return base;
    }

private:
    void transpose(int y, float* destination) const {
        for (const FeatureMap* source : sources_) {
            const int channels = source->channels();
            const float* pixels = source->pixel(y % source->height(), 0);  // rings: row y at y % height
            switch (channels) {
            case 1:
                std::memcpy(destination, pixels, std::size_t(width_) * sizeof(float));
                break;
            case 3:
                deinterleave<3>(pixels, destination);
                break;
            case 8:
                transposeEights(pixels, destination);
                break;
            default:
                deinterleave<0>(pixels, destination, channels);
                break;
            }
            destination += std::size_t(channels) * stride_;
        }
    }

    // Eight channels: eight pixels at a time through an 8x8 register transpose (unpack pairs,
    // then pairs of pairs, then halves): 24 shuffles instead of 64 scalar loads and stores.
    void transposeEights(const float* pixels, float* planes) const {
        int x = 0;
        for (; x + kLanes <= width_; x += kLanes) {
            Vec8f r[8];
            for (int p = 0; p < 8; ++p) r[p] = load8(pixels + std::size_t(x + p) * 8);
            Vec8f t[8], u[8];
            for (int p = 0; p < 8; p += 2) {
                t[p] = __builtin_shufflevector(r[p], r[p + 1], 0, 8, 1, 9, 4, 12, 5, 13);
                t[p + 1] = __builtin_shufflevector(r[p], r[p + 1], 2, 10, 3, 11, 6, 14, 7, 15);
            }
            for (int q = 0; q < 8; q += 4) {
                for (int h = 0; h < 2; ++h) {
                    u[q + 2 * h] = __builtin_shufflevector(t[q + h], t[q + h + 2], 0, 1, 8, 9, 4, 5, 12, 13);
                    u[q + 2 * h + 1] = __builtin_shufflevector(t[q + h], t[q + h + 2], 2, 3, 10, 11, 6, 7, 14, 15);
                }
            }
            for (int c = 0; c < 4; ++c) {
                const Vec8f low = __builtin_shufflevector(u[c], u[c + 4], 0, 1, 2, 3, 8, 9, 10, 11);
                const Vec8f high = __builtin_shufflevector(u[c], u[c + 4], 4, 5, 6, 7, 12, 13, 14, 15);
                std::memcpy(planes + std::size_t(c) * stride_ + x, &low, sizeof low);
                std::memcpy(planes + std::size_t(c + 4) * stride_ + x, &high, sizeof high);
            }
        }
        for (; x < width_; ++x) {
            for (int c = 0; c < 8; ++c) planes[std::size_t(c) * stride_ + x] = pixels[std::size_t(x) * 8 + c];
        }
    }

    // Pixel by pixel: contiguous reads, and with the channel count known at compile time the
    // inner loop unrolls.
    template <int kChannels>
    void deinterleave(const float* pixels, float* planes, int runtimeChannels = 0) const {
        const int channels = kChannels > 0 ? kChannels : runtimeChannels;
        for (int x = 0; x < width_; ++x) {
            const float* pixel = pixels + std::size_t(x) * channels;
            for (int c = 0; c < channels; ++c) planes[std::size_t(c) * stride_ + x] = pixel[c];
        }
    }

    std::vector<const FeatureMap*> sources_;
    int width_;
    int pad_;
    int planes_ = 0;
    std::size_t stride_ = 0;
    int slots_ = 1;
    std::vector<int> slotRow_;
    std::vector<float> storage_;
};

// A map must be `width` x `channels` and either the whole image (`imageHeight` rows) or a ring
// of at least `ringRows` rows (ringRows = imageHeight: the whole image only).
void checkMap(const FeatureMap& map, const char* name, int imageHeight, int ringRows, int width, int channels) {
    const bool heightFits = map.height() == imageHeight || (map.height() >= ringRows && map.height() < imageHeight);
    if (!heightFits || map.width() != width || map.channels() != channels) {
        throw Error(std::string("affinity filter: ") + name + " is " + std::to_string(map.height()) + " x " +
                    std::to_string(map.width()) + " x " + std::to_string(map.channels()) + ", expected " +
                    std::to_string(imageHeight) + " x " + std::to_string(width) + " x " + std::to_string(channels) +
                    (ringRows < imageHeight ? " (or a ring of at least " + std::to_string(ringRows) + " rows)" : ""));
    }
}

// `ringRows`: the fewest rows a ring input may hold for this call (imageHeight: no rings).
void checkInputs(const FeatureMap& radiance, const KernelParams& kernel, int tapSize, int dilation,
                 const TemporalTaps* temporal, int imageHeight, int ringRows) {
    if (kernel.features == nullptr || kernel.bandwidth == nullptr || kernel.centre == nullptr) {
        throw Error("affinity filter: a kernel parameter map is missing");
    }
    if (tapSize < 1 || tapSize % 2 == 0) {
        throw Error("affinity filter: the tap grid size " + std::to_string(tapSize) + " is not a positive odd number");
    }
    if (dilation < 1) throw Error("affinity filter: dilation " + std::to_string(dilation) + " is below 1");
    const int width = radiance.width();
    const int features = kernel.features->channels();
    if (features < 1) throw Error("affinity filter: the kernel has no features");
    const int channels = radiance.channels();
    if (channels != kSignalChannels)
        throw Error("affinity filter: the filtered signal has " + std::to_string(channels) +
                    " channels, expected 3 (RGB radiance)");
    checkMap(radiance, "the filtered signal", imageHeight, ringRows, width, channels);
    checkMap(*kernel.features, "the features", imageHeight, ringRows, width, features);
    checkMap(*kernel.bandwidth, "the bandwidth a", imageHeight, ringRows, width, 1);
    checkMap(*kernel.centre, "the centre weight c", imageHeight, ringRows, width, 1);
    if (temporal != nullptr) {
        checkMap(*temporal->bandwidth, "the temporal bandwidth b", imageHeight, ringRows, width, 1);
        checkMap(*temporal->output, "the warped output", imageHeight, ringRows, width, channels);
        checkMap(*temporal->features, "the warped features", imageHeight, ringRows, width, features);
        checkMap(*temporal->valid, "the warped validity", imageHeight, ringRows, width, 1);
        if (!(temporal->guardRatio >= 0.0f) || !(temporal->guardFloor >= 0.0f) ||
            !std::isfinite(temporal->guardRatio) || !std::isfinite(temporal->guardFloor))
            throw Error("affinity filter: the bright-history guard's ratio " + std::to_string(temporal->guardRatio) +
                        " and floor " + std::to_string(temporal->guardFloor) + " must be finite and not negative");
    }
}

bool isInput(const FeatureMap& map, const FeatureMap& radiance, const KernelParams& kernel,
             const TemporalTaps* temporal) {
    return &map == &radiance || &map == kernel.features || &map == kernel.bandwidth || &map == kernel.centre ||
           (temporal != nullptr && (&map == temporal->bandwidth || &map == temporal->output ||
                                    &map == temporal->features || &map == temporal->valid));
}

// 16 lanes for AVX-512 (the same bits as 8); the caller has checked that the CPU has it.
FilterRowFunction rowFunction(ConvIsa isa, bool temporal, int features) {
#if AFFINITY_HAVE_AVX512_KERNEL
    if (isa == ConvIsa::Avx512) return filterRowFunctionAvx512(temporal, features);
#endif
    return filterRowFunction<8>(temporal, features);
}

// The shared driver of both passes: rows in parallel, each thread with its own planar rows.
void runFilterRows(const FeatureMap& radiance, const KernelParams& kernel, int tapSize, int dilation,
                   const TemporalTaps* temporal, int imageHeight, int begin, int end, FeatureMap& output,
                   ConvIsa isa = defaultConvIsa()) {
    if (begin < 0 || end > imageHeight || begin > end)
        throw Error("affinity filter: rows " + std::to_string(begin) + ".." + std::to_string(end) +
                    " are not inside an image of " + std::to_string(imageHeight) + " rows");
    if (begin == end || radiance.width() == 0) return;
    const int radius = tapSize / 2;
    const int pad = radius * dilation;
    // A ring must hold every row one call reads at once.
    const int ringRows = std::min(imageHeight, end - begin + 2 * std::max(pad, temporal != nullptr ? 1 : 0));
    checkInputs(radiance, kernel, tapSize, dilation, temporal, imageHeight, ringRows);
    // Writing into a buffer that is also read would race between rows.
    if (isInput(output, radiance, kernel, temporal)) throw Error("affinity filter: the output is one of the inputs");
    checkMap(output, "the output", imageHeight, std::min(imageHeight, end - begin), radiance.width(),
             radiance.channels());
    const int width = radiance.width();
    const int features = kernel.features->channels();

    std::vector<const FeatureMap*> spatialSources = {kernel.features, &radiance, kernel.bandwidth, kernel.centre};
    if (temporal != nullptr) spatialSources.push_back(temporal->bandwidth);
    if (isa == ConvIsa::Avx512 && !cpuHasAvx512())
        throw Error("affinity filter: the AVX-512 path was asked for, but this CPU or build has no AVX-512");
    const FilterRowFunction filterRowFunctionFor = rowFunction(isa, temporal != nullptr, features);

    // Allocated outside the parallel region so that an allocation failure throws normally.
    const int threads = std::max(1, omp_get_max_threads());
    std::vector<PlanarRows> spatialRows, temporalRows;
    for (int t = 0; t < threads; ++t) {
        spatialRows.emplace_back(spatialSources, std::max(pad, 1), 2 * pad + 1);
        if (temporal != nullptr) {
            temporalRows.emplace_back(
                std::vector<const FeatureMap*>{temporal->features, temporal->output, temporal->valid}, 1, 3);
        }
    }

#pragma omp parallel num_threads(threads)
    {
        const int thread = omp_get_thread_num();
        PlanarRows& spatial = spatialRows[std::size_t(thread)];
        PlanarRows* temporalCache = temporal != nullptr ? &temporalRows[std::size_t(thread)] : nullptr;
        std::vector<const float*> taps(std::size_t(tapSize), nullptr);
        const float* temporalTaps[3] = {nullptr, nullptr, nullptr};
        // Contiguous blocks of rows per thread, so each thread's ring reuses its rows.
#pragma omp for schedule(static)
        for (int y = begin; y < end; ++y) {
            for (int j = 0; j < tapSize; ++j) {
                const int tapY = y + (j - radius) * dilation;
                taps[std::size_t(j)] = tapY >= 0 && tapY < imageHeight ? spatial.row(tapY) : nullptr;
            }
            // After the neighbours: the centre row must stay in its slot (it is one of them).
            FilterRowInputs in{};
            in.width = width;
            in.features = features;
            in.stride = spatial.stride();
            in.centre = taps[std::size_t(radius)];
            in.taps = taps.data();
            in.tapSize = tapSize;
            in.dilation = dilation;
            if (temporalCache != nullptr) {
                for (int j = 0; j < 3; ++j) {
                    const int tapY = y + j - 1;
                    temporalTaps[j] = tapY >= 0 && tapY < imageHeight ? temporalCache->row(tapY) : nullptr;
                }
                in.temporalStride = temporalCache->stride();
                in.guardRatio = temporal->guardRatio;
                in.guardFloor = temporal->guardFloor;
                in.temporalRows = temporalTaps;
            }
            filterRowFunctionFor(in, output.pixel(y % output.height(), 0));
        }
    }
}

// A whole image: the output sized here, and written through a separate buffer when it is an input.
void runFilter(const FeatureMap& radiance, const KernelParams& kernel, int tapSize, int dilation,
               const TemporalTaps* temporal, FeatureMap& output) {
    const int height = radiance.height();
    checkInputs(radiance, kernel, tapSize, dilation, temporal, height, height);
    const bool outputIsInput = isInput(output, radiance, kernel, temporal);
    FeatureMap separate;
    FeatureMap& target = outputIsInput ? separate : output;
    target.resize(height, radiance.width(), radiance.channels());
    runFilterRows(radiance, kernel, tapSize, dilation, temporal, height, 0, height, target);
    if (outputIsInput) output = std::move(separate);
}

}  // namespace

void affinityFilter(const FeatureMap& radiance, const KernelParams& kernel, int tapSize, int dilation,
                    FeatureMap& output) {
    runFilter(radiance, kernel, tapSize, dilation, nullptr, output);
}

void affinityFilterTemporal(const FeatureMap& radiance, const KernelParams& kernel, int tapSize, int dilation,
                            const FeatureMap& temporalBandwidth, const FeatureMap& warpedOutput,
                            const FeatureMap& warpedFeatures, const FeatureMap& warpedValid, FeatureMap& output) {
    const TemporalTaps temporal{&temporalBandwidth, &warpedOutput, &warpedFeatures, &warpedValid};
    runFilter(radiance, kernel, tapSize, dilation, &temporal, output);
}

void affinityFilterRows(const FeatureMap& radiance, const KernelParams& kernel, int tapSize, int dilation,
                        const TemporalTaps* temporal, int imageHeight, int begin, int end, FeatureMap& output) {
    runFilterRows(radiance, kernel, tapSize, dilation, temporal, imageHeight, begin, end, output);
}

void affinityFilterRows(const FeatureMap& radiance, const KernelParams& kernel, int tapSize, int dilation,
                        const TemporalTaps* temporal, int imageHeight, int begin, int end, FeatureMap& output,
                        ConvIsa isa) {
    runFilterRows(radiance, kernel, tapSize, dilation, temporal, imageHeight, begin, end, output, isa);
}

}  // namespace affinity
