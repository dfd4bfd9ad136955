#include "pipeline/stages.h"

#include <algorithm>
#include <cstring>

#include "affinity/error.h"
#include "kernels/affinity_filter.h"
#include "kernels/bilinear_warp.h"
#include "kernels/catmull_rom_warp.h"
#include "kernels/fast_exp.h"
#include "network/filter_signal.h"
#include "pipeline/band_schedule.h"
#include "pipeline/history_guard.h"

namespace affinity {

// The per-pixel parameters of the filters (docs/MODEL.md section 5). Rings of bandRingRows()
// rows except the last kernel's features, which the next frame's temporal taps read.
struct KernelMaps {
    std::vector<FeatureMap> features, bandwidth, centre;  // per kernel: F channels, 1, 1
    FeatureMap temporalBandwidth;                         // 1 channel

    KernelParams kernel(int k) const {
        const std::size_t i = std::size_t(k);
        return KernelParams{&features[i], &bandwidth[i], &centre[i]};
    }
};

namespace {

// Sigmoid in place on `count` contiguous values, eight at a time (the last group padded), so
// every value goes through the same vector code whatever the tiling.
void sigmoidInPlace(float* values, int count) {
    int i = 0;
    for (; i + 8 <= count; i += 8) {  // constant-size copies: register moves, not library calls
        Vec8f x;
        std::memcpy(&x, values + i, sizeof x);
        const Vec8f y = fastSigmoid(x);
        std::memcpy(values + i, &y, sizeof y);
    }
    if (i < count) {
        const std::size_t bytes = std::size_t(count - i) * sizeof(float);
        Vec8f x{};
        std::memcpy(&x, values + i, bytes);
        const Vec8f y = fastSigmoid(x);
        std::memcpy(values + i, &y, bytes);
    }
}

// Copies `count` floats; today's count of a pixel's affinity features (8) with a constant size,
// which compiles to register moves where std::copy of a run-time count is a memmove call per
// pixel (tens of ms per 1080p frame).
inline void copyPixel(const float* from, int count, float* to) {
    if (count == 8)
        std::memcpy(to, from, 8 * sizeof(float));
    else
        std::copy(from, from + count, to);
}

// warped = current wherever the history is not valid.
void keepWhereValid(FeatureMap& warped, const FeatureMap& current, const float* valid) {
    const int channels = current.channels();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < current.height(); ++y)
        for (int x = 0; x < current.width(); ++x)
            if (!(valid[std::size_t(y) * std::size_t(current.width()) + std::size_t(x)] > 0.5f)) {
                const float* from = current.pixel(y, x);
                std::copy(from, from + channels, warped.pixel(y, x));
            }
}

// Rows of the kernel parameters made per band (band_schedule.h). Each thread transposes its
// rows' tap halo again per band, so bands much shorter cost time; at 1080p the peak memory was
// lowest around 128 rows, with equal time from 32 rows to the whole image (bench_denoiser).
constexpr int kBandRows = 128;

}  // namespace

void InterruptCheck::operator()() const {
    if (check && check()) throw Interrupted("denoise: interrupted");
}

Accumulated Stages::warpHistory(const FeatureMap& embedding, const FeatureMap& signal, SequenceHistory& sequence,
                                bool history, const float* motion, const float* valid) {
    const int height = embedding.height(), width = embedding.width();
    Accumulated accumulated;
    accumulated.embedding = pool_.take(height, width, embedding.channels());
    accumulated.signal = pool_.take(height, width, signal.channels());
    if (history) {
        // Radiance sharp (a blurred history blurs the output), embeddings bilinear (cheaper).
        warpBilinear(sequence.embedding, motion, accumulated.embedding);
        warpCatmullRom(sequence.signal, motion, accumulated.signal);
        keepWhereValid(accumulated.embedding, embedding, valid);
        keepWhereValid(accumulated.signal, signal, valid);
    } else {
        accumulated.embedding = embedding;
        accumulated.signal = signal;
    }
    pool_.give(sequence.embedding);  // read: their memory serves the U-Net
    pool_.give(sequence.signal);
    return accumulated;
}

void Stages::runBlock(const std::vector<Conv2d>& block, std::size_t first, std::size_t end, FeatureMap& map) {
    for (std::size_t j = first; j < end; ++j) {
        interrupted_();
        FeatureMap next = pool_.take(map.height(), map.width(), block[j].outChannels());
        block[j].apply(map, Activation::LeakyRelu, next);
        pool_.give(map);
        map = std::move(next);
    }
}

UnetTail Stages::unet(const FeatureMap& embedding, const FeatureMap& historyEmbedding) {
    const Network& net = net_;
    const std::size_t levels = net.encoder.size();
    std::vector<FeatureMap> encoderOut(levels);  // the skip connections
    for (std::size_t level = 0; level < levels; ++level) {
        interrupted_();
        const std::vector<Conv2d>& block = net.encoder[level];
        FeatureMap& out = encoderOut[level];
        if (level == 0) {
            out = pool_.take(embedding.height(), embedding.width(), block[0].outChannels());
            block[0].apply(embedding, historyEmbedding, Activation::LeakyRelu, out);
        } else {
            const FeatureMap& above = encoderOut[level - 1];
            FeatureMap pooled = pool_.take((above.height() + 1) / 2, (above.width() + 1) / 2, above.channels());
            maxPool2x2(above, pooled);
            out = pool_.take(pooled.height(), pooled.width(), block[0].outChannels());
            block[0].apply(pooled, Activation::LeakyRelu, out);
            pool_.give(pooled);
        }
        runBlock(block, 1, block.size(), out);
    }
    const FeatureMap& deepest = encoderOut[levels - 1];
    FeatureMap low = pool_.take((deepest.height() + 1) / 2, (deepest.width() + 1) / 2, deepest.channels());
    maxPool2x2(deepest, low);
    runBlock(net.bottleneck, 0, net.bottleneck.size(), low);
    // Decoder levels, the coarser level read upsampled; level 0 stops before its last convolution.
    for (std::size_t l = levels; l-- > 0;) {
        interrupted_();
        FeatureMap& skip = encoderOut[l];
        const std::vector<Conv2d>& block = net.decoder[l];
        if (l == 0 && block.size() == 1) return UnetTail{std::move(low), std::move(skip)};
        FeatureMap out = pool_.take(skip.height(), skip.width(), block[0].outChannels());
        block[0].applyUpsampled(low, skip, Activation::LeakyRelu, out);
        pool_.give(low);
        pool_.give(skip);
        runBlock(block, 1, l == 0 ? block.size() - 1 : block.size(), out);
        low = std::move(out);
    }
    return UnetTail{FeatureMap(), std::move(low)};
}

void Stages::give(UnetTail& tail) {
    pool_.give(tail.coarse);
    pool_.give(tail.input);
}

KernelMaps Stages::takeKernelMaps(int height, int width, int ringRows) {
    KernelMaps maps;
    for (int k = 0; k < net_.kernels; ++k) {
        maps.features.push_back(pool_.take(k + 1 == net_.kernels ? height : ringRows, width, net_.affinityFeatures));
        maps.bandwidth.push_back(pool_.take(ringRows, width, 1));
        maps.centre.push_back(pool_.take(ringRows, width, 1));
    }
    maps.temporalBandwidth = pool_.take(ringRows, width, 1);
    return maps;
}

void Stages::give(KernelMaps& maps) {
    for (std::vector<FeatureMap>* list : {&maps.features, &maps.bandwidth, &maps.centre})
        for (FeatureMap& map : *list) pool_.give(map);
    pool_.give(maps.temporalBandwidth);
}

// The last full-resolution convolution and the head, fused tile by tile so that neither
// full-resolution output exists as a whole: each tile's head output goes straight into the
// parameter maps (rings: row y at y % height), and its lambda into the accumulation.
void Stages::parametersAndAccumulation(const UnetTail& tail, int begin, int end, KernelMaps& maps,
                                       const FeatureMap& embedding, const FeatureMap& signal, Accumulated& accumulated,
                                       FeatureMap& filterIn) {
    const Network& net = net_;
    FeatureMap& historyEmbedding = accumulated.embedding;
    FeatureMap& historySignal = accumulated.signal;
    const int rows = tail.input.height(), columns = tail.input.width();
    const int K = net.kernels, F = net.affinityFeatures;
    const int G = net.kernelChannels();  // head channels per kernel (docs/MODEL.md section 5)
    const Conv2d& last = net.decoder[0].back();
    const Conv2d& head = *net.head;
    const std::vector<ConvSource> sources = tail.sources();
    int sourceChannels = 0;
    for (const ConvSource& source : sources) sourceChannels += source.channels;
    // Checked here: an exception cannot leave the parallel region below.
    if (sourceChannels != last.inChannels() || head.inChannels() != last.outChannels() ||
        head.outChannels() != net.headChannels())
        throw Error("denoise: the model's last layers do not fit together");
    const int E = embedding.channels(), C = filterIn.channels();
    if (C != signal.channels())
        throw Error("denoise: the filter's input and the accumulated signal differ in channels");
    const int tiles = (columns + kConvTileWidth - 1) / kConvTileWidth;
    // The convolution runs kWinogradRows rows at a time (its Winograd form's tiles); a group
    // reaching past the band is recomputed by the neighbouring band, but only the band's rows go on.
    const int firstGroup = begin / kWinogradRows, endGroup = (end + kWinogradRows - 1) / kWinogradRows;
    const long long tasks = (long long)(endGroup - firstGroup) * tiles;
#pragma omp parallel
    {
        std::vector<float> decoded[kWinogradRows];
        for (std::vector<float>& row : decoded) row.resize(std::size_t(columns) * std::size_t(last.outChannels()));
        std::vector<float> params(std::size_t(columns) * std::size_t(head.outChannels()));
        // A tile's lambda: only its accumulation reads it.
        std::vector<float> lambda(kConvTileWidth);
#pragma omp for schedule(dynamic)
        for (long long task = 0; task < tasks; ++task) {
            const int y0 = kWinogradRows * (firstGroup + int(task / tiles));
            const int x0 = int(task % tiles) * kConvTileWidth;
            const int x1 = std::min(columns, x0 + kConvTileWidth);
            float* decodedRows[kWinogradRows];
            for (int r = 0; r < kWinogradRows; ++r) decodedRows[r] = y0 + r < rows ? decoded[r].data() : nullptr;
            last.applyRowGroup(sources.data(), int(sources.size()), rows, columns, y0, x0, x1, Activation::LeakyRelu,
                               decodedRows);
            for (int y = std::max(y0, begin); y < std::min(y0 + kWinogradRows, end); ++y) {
                const ConvSource decodedRow{decoded[y - y0].data(), last.outChannels()};
                head.applyRow(&decodedRow, 1, 1, columns, 0, x0, x1, Activation::None, params.data());
                // Scatter the head's channels into the maps, then the sigmoids on each single-channel
                // map's contiguous stretch of this tile. Rings hold row y at y % height: one division
                // per map and tile (one per pixel made this stage measurably slower).
                auto row = [y](FeatureMap& map) { return map.pixel(y % map.height(), 0); };
                for (std::size_t k = 0; k < std::size_t(K); ++k) {
                    float* features = row(maps.features[k]);
                    float* bandwidth = row(maps.bandwidth[k]);
                    float* centre = row(maps.centre[k]);
                    for (int x = x0; x < x1; ++x) {
                        const float* base =
                            params.data() + std::size_t(x) * std::size_t(head.outChannels()) + int(k) * G;
                        copyPixel(base, F, features + std::size_t(x) * F);
                        bandwidth[x] = base[F];
                        centre[x] = base[F + 1];
                    }
                    sigmoidInPlace(centre + x0, x1 - x0);
                }
                float* temporalBandwidth = row(maps.temporalBandwidth);
                for (int x = x0; x < x1; ++x) {
                    const float* o = params.data() + std::size_t(x) * std::size_t(head.outChannels());
                    temporalBandwidth[x] = o[K * G];
                    lambda[std::size_t(x - x0)] = o[K * G + 1];
                }
                sigmoidInPlace(lambda.data(), x1 - x0);
                // 3 (continued). history = (1 - lambda) current + lambda history, in place; the
                // kernels filter the accumulated signal.
                // The filtered copy is stored from the same values: reading the just-stored floats
                // back as one wider load stalled on store forwarding.
                float* filtered = row(filterIn);
                for (int x = x0; x < x1; ++x) {
                    const float l = lambda[std::size_t(x - x0)];
                    const float* e = embedding.pixel(y, x);
                    float* h = historyEmbedding.pixel(y, x);
                    for (int c = 0; c < E; ++c) h[c] = (1.0f - l) * e[c] + l * h[c];
                    const float* current = signal.pixel(y, x);
                    float* accumulatedSignal = historySignal.pixel(y, x);
                    float* f = filtered + std::size_t(x) * C;
                    for (int c = 0; c < C; ++c)
                        f[c] = accumulatedSignal[c] = (1.0f - l) * current[c] + l * accumulatedSignal[c];
                }
            }
        }
    }
}

void Stages::filterInBands(const UnetTail& tail, const FeatureMap& embedding, const FeatureMap& signal,
                           Accumulated& accumulated, const float* motion, const float* valid, KernelChoice choice,
                           SequenceHistory& sequence, StageClock& clock) {
    const Network& net = net_;
    FeatureMap& output = sequence.output;
    FeatureMap& lastFeatures = sequence.lastFeatures;
    const int height = embedding.height(), width = embedding.width();
    const int K = net.kernels, F = net.affinityFeatures, C = kSignalChannels;
    // The kernels that run, in order (all K, or the last alone), and how far their taps reach.
    std::vector<int> kernels, radii;
    for (int k = choice.allKernels ? 0 : K - 1; k < K; ++k) {
        kernels.push_back(k);
        radii.push_back((net.tapSize / 2) << k);
    }
    const bool temporal = choice.temporal;
    const int ringRows = bandRingRows(height, kBandRows, radii);
    KernelMaps params = takeKernelMaps(height, width, ringRows);
    FeatureMap filterIn = pool_.take(ringRows, width, C);
    std::vector<FeatureMap> between;  // the output of each kernel but the last
    for (std::size_t i = 0; i + 1 < kernels.size(); ++i) between.push_back(pool_.take(ringRows, width, C));
    FeatureMap newOutput = pool_.take(height, width, C);
    FeatureMap warpedOutput, warpedFeatures, warpedValid;  // the temporal taps' rows
    if (temporal) {
        warpedOutput = pool_.take(ringRows, width, C);
        warpedFeatures = pool_.take(ringRows, width, F);
        warpedValid = pool_.take(ringRows, width, 1);
    }
    int warpedEnd = 0;
    const TemporalTaps taps{&params.temporalBandwidth,
                            &warpedOutput,
                            &warpedFeatures,
                            &warpedValid,
                            temporal && choice.historyGuard ? kHistoryGuardRatio : 0.0f,
                            temporal && choice.historyGuard ? historyGuardFloor(signal) : 0.0f};

    double parameterMs = 0.0, spatialMs = 0.0, temporalMs = 0.0;
    for (const BandStep& step : bandSchedule(height, kBandRows, radii)) {
        interrupted_();
        auto start = std::chrono::steady_clock::now();
        parametersAndAccumulation(tail, step.begin, step.end, params, embedding, signal, accumulated, filterIn);
        parameterMs += millisecondsSince(start);
        for (std::size_t i = 0; i < kernels.size(); ++i) {
            const auto [begin, end] = step.stages[i];
            if (begin == end) continue;
            start = std::chrono::steady_clock::now();
            const int k = kernels[i];
            const bool last = i + 1 == kernels.size();
            const FeatureMap& in = i == 0 ? filterIn : between[i - 1];
            FeatureMap& out = last ? newOutput : between[i];
            if (last && temporal) {
                // 7. The last kernel with temporal taps on the warped previous output: one row
                // each way of warped rows.
                const int warpTo = std::min(height, end + 1);
                warpBilinearRows(lastFeatures, motion, warpedEnd, warpTo, warpedFeatures);
                warpCatmullRomRows(output, motion, warpedEnd, warpTo, warpedOutput);
                // The model's temporal gain scales what every valid tap gives (docs/MODEL.md section 7).
                for (int y = warpedEnd; y < warpTo; ++y)
                    std::transform(valid + std::size_t(y) * width, valid + std::size_t(y + 1) * width,
                                   warpedValid.pixel(y % ringRows, 0),
                                   [gain = net.temporalGain](float v) { return v * gain; });
                warpedEnd = warpTo;
                affinityFilterRows(in, params.kernel(k), net.tapSize, 1 << k, &taps, height, begin, end, out);
            } else {
                // 6. A dilated spatial kernel.
                affinityFilterRows(in, params.kernel(k), net.tapSize, 1 << k, nullptr, height, begin, end, out);
            }
            (last && temporal ? temporalMs : spatialMs) += millisecondsSince(start);
        }
    }
    clock.add("kernel parameters and accumulation", parameterMs);
    clock.add("spatial kernels", spatialMs);
    clock.add("temporal kernel", temporalMs);

    std::swap(output, newOutput);
    pool_.give(newOutput);
    pool_.give(lastFeatures);
    lastFeatures = std::move(params.features[std::size_t(K - 1)]);
    give(params);
    for (FeatureMap* map : {&filterIn, &warpedOutput, &warpedFeatures, &warpedValid}) pool_.give(*map);
    for (FeatureMap& map : between) pool_.give(map);
}

}  // namespace affinity
