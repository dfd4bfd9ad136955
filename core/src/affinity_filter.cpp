#include "affinity_filter.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include "affinity/error.h"
#include "affinity_strips.h"
#include "conv_kernel.h"

namespace affinity {
namespace {

constexpr int kLanes = 8;  // of the row transposes and the warp
// Filtered signals: RGB radiance, or demodulated diffuse RGB + specular RGB (filter_signal.h).
constexpr int kSignalChannelCounts[] = {3, 6};

Vec8f load8(const float* p) {
    Vec8f v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

// Planar, zero-padded copies of image rows. The inputs are NHWC (a pixel's channels adjacent);
// the kernels want each channel's row contiguous so that eight neighbouring pixels are one
// vector load (indexing NHWC per channel makes the compiler gather: 100 ms against 22 ms per
// pass in shared/design/FACTS.md). Each row
// is transposed once per thread into a ring of slots covering the rows a kernel reaches.
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
                case 1: std::memcpy(destination, pixels, std::size_t(width_) * sizeof(float)); break;
                case 3: deinterleave<3>(pixels, destination); break;
                case 6: deinterleave<6>(pixels, destination); break;
                case 8: transposeEights(pixels, destination); break;
                default: deinterleave<0>(pixels, destination, channels); break;
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

// Rows [begin, end) of warpBilinearRows (checked by the caller); kChannels > 0 fixes the
// channel count at compile time, 0 reads it from the maps.
template <int kChannels>
void warpRows(const FeatureMap& previous, const float* motion, int begin, int end, FeatureMap& output) {
    const int height = previous.height(), width = previous.width();
    const int channels = kChannels > 0 ? kChannels : previous.channels();
    const std::size_t rowFloats = std::size_t(width) * channels;
#pragma omp parallel for schedule(static)
    for (int y = begin; y < end; ++y) {
        for (int xBlock = 0; xBlock < width; xBlock += kLanes) {
            // Positions, taps and weights for eight pixels at once (this part vectorises), then
            // the channel loops pixel by pixel.
            const int count = std::min(kLanes, width - xBlock);
            const float* m = motion + 2 * (std::size_t(y) * width + xBlock);
            std::size_t top[kLanes], bottom[kLanes];
            int left[kLanes], right[kLanes];
            float fx[kLanes], fy[kLanes];
#pragma omp simd
            for (int l = 0; l < count; ++l) {
                // Clamping the position to one pixel beyond the border first keeps the integer
                // conversion defined for any motion (even NaN or huge values) and changes
                // nothing: both taps clamp to the border pixel there anyway.
                float sx = float(xBlock + l) + m[2 * l], sy = float(y) + m[2 * l + 1];
                sx = sx >= -1.0f ? (sx <= float(width) ? sx : float(width)) : -1.0f;
                sy = sy >= -1.0f ? (sy <= float(height) ? sy : float(height)) : -1.0f;
                const float floorX = std::floor(sx), floorY = std::floor(sy);
                fx[l] = sx - floorX;
                fy[l] = sy - floorY;
                const int x0 = int(floorX), y0 = int(floorY);
                left[l] = std::clamp(x0, 0, width - 1) * channels;
                right[l] = std::clamp(x0 + 1, 0, width - 1) * channels;
                top[l] = std::size_t(std::clamp(y0, 0, height - 1)) * rowFloats;
                bottom[l] = std::size_t(std::clamp(y0 + 1, 0, height - 1)) * rowFloats;
            }
            for (int l = 0; l < count; ++l) {
                const float* p00 = previous.data() + top[l] + left[l];
                const float* p01 = previous.data() + top[l] + right[l];
                const float* p10 = previous.data() + bottom[l] + left[l];
                const float* p11 = previous.data() + bottom[l] + right[l];
                const float w00 = (1 - fx[l]) * (1 - fy[l]), w01 = fx[l] * (1 - fy[l]);
                const float w10 = (1 - fx[l]) * fy[l], w11 = fx[l] * fy[l];
                float* out = output.pixel(y % output.height(), xBlock + l);
#pragma omp simd
                for (int c = 0; c < channels; ++c) {
                    out[c] = w00 * p00[c] + w01 * p01[c] + w10 * p10[c] + w11 * p11[c];
                }
            }
        }
    }
}

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
    if (std::find(std::begin(kSignalChannelCounts), std::end(kSignalChannelCounts), channels) ==
        std::end(kSignalChannelCounts))
        throw Error("affinity filter: the filtered signal has " + std::to_string(channels) +
                    " channels, expected 3 (radiance) or 6 (demodulated diffuse and specular)");
    checkMap(radiance, "the filtered signal", imageHeight, ringRows, width, channels);
    checkMap(*kernel.features, "the features", imageHeight, ringRows, width, features);
    checkMap(*kernel.bandwidth, "the bandwidth a", imageHeight, ringRows, width, 1);
    checkMap(*kernel.centre, "the centre weight c", imageHeight, ringRows, width, 1);
    if (kernel.source != nullptr) checkMap(*kernel.source, "the source weight s", imageHeight, ringRows, width, 1);
    if (temporal != nullptr) {
        checkMap(*temporal->bandwidth, "the temporal bandwidth b", imageHeight, ringRows, width, 1);
        checkMap(*temporal->output, "the warped output", imageHeight, ringRows, width, channels);
        checkMap(*temporal->features, "the warped features", imageHeight, ringRows, width, features);
        checkMap(*temporal->valid, "the warped validity", imageHeight, ringRows, width, 1);
    }
}

bool isInput(const FeatureMap& map, const FeatureMap& radiance, const KernelParams& kernel,
             const TemporalTaps* temporal) {
    return &map == &radiance || &map == kernel.features || &map == kernel.bandwidth || &map == kernel.centre ||
           &map == kernel.source ||
           (temporal != nullptr && (&map == temporal->bandwidth || &map == temporal->output ||
                                    &map == temporal->features || &map == temporal->valid));
}

// 16 lanes for AVX-512 (the same bits as 8); the caller has checked that the CPU has it.
FilterRowFunction rowFunction(ConvIsa isa, bool temporal, int features, int channels) {
#if AFFINITY_HAVE_AVX512_KERNEL
    if (isa == ConvIsa::Avx512) return filterRowFunctionAvx512(temporal, features, channels);
#endif
    return filterRowFunction<8>(temporal, features, channels);
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
    if (kernel.source != nullptr) spatialSources.push_back(kernel.source);
    if (temporal != nullptr) spatialSources.push_back(temporal->bandwidth);
    if (isa == ConvIsa::Avx512 && !cpuHasAvx512())
        throw Error("affinity filter: the AVX-512 path was asked for, but this CPU or build has no AVX-512");
    const FilterRowFunction filterRowFunctionFor = rowFunction(isa, temporal != nullptr, features, radiance.channels());

    // Allocated outside the parallel region so that an allocation failure throws normally.
    const int threads = std::max(1, omp_get_max_threads());
    std::vector<PlanarRows> spatialRows, temporalRows;
    for (int t = 0; t < threads; ++t) {
        spatialRows.emplace_back(spatialSources, std::max(pad, 1), 2 * pad + 1);
        if (temporal != nullptr) {
            temporalRows.emplace_back(std::vector<const FeatureMap*>{temporal->features, temporal->output, temporal->valid}, 1, 3);
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
            in.sourceWeights = kernel.source != nullptr;
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

void warpBilinear(const FeatureMap& previous, const float* motion, FeatureMap& output) {
    if (&output == &previous) throw Error("warpBilinear: the output must not be the input");
    output.resize(previous.height(), previous.width(), previous.channels());
    warpBilinearRows(previous, motion, 0, previous.height(), output);
}

void warpBilinearRows(const FeatureMap& previous, const float* motion, int begin, int end, FeatureMap& output) {
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
    if (begin == end || width == 0) return;
    if (motion == nullptr) throw Error("warpBilinear: no motion vectors");
    // The channel counts of today's maps (signal 3, features 8, embedding 16 or 32) with a
    // constant count: the pixel's blend then compiles to a few whole-vector operations.
    switch (channels) {
        case 3: warpRows<3>(previous, motion, begin, end, output); break;
        case 8: warpRows<8>(previous, motion, begin, end, output); break;
        case 16: warpRows<16>(previous, motion, begin, end, output); break;
        case 32: warpRows<32>(previous, motion, begin, end, output); break;
        default: warpRows<0>(previous, motion, begin, end, output);
    }
}

}  // namespace affinity
