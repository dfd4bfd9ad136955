// The per-frame pipeline of docs/MODEL.md: embedding -> warp and accumulate -> U-Net ->
// per-pixel kernel parameters -> dilated affinity kernels -> temporal kernel.
#include "affinity/denoiser.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>

#include "affinity/error.h"
#include "kernels/affinity_filter.h"
#include "kernels/bilinear_warp.h"
#include "kernels/catmull_rom_warp.h"
#include "pipeline/band_schedule.h"
#include "pipeline/exposure.h"
#include "kernels/fast_exp.h"
#include "pipeline/feature_map_pool.h"
#include "network/filter_signal.h"
#include "network/network.h"

namespace affinity {
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

// How much larger than a request a free map may be and still serve it while a frame is lent in
// bands (Denoiser::sampleBands; FeatureMapPool::kKeepRatio otherwise).
constexpr std::size_t kLentKeepRatio = 2;

// 1 / mean depth of the samples that hit something, over every kDepthScaleRowStep-th row
// (docs/MODEL.md section 1). Rows are summed in parallel and their sums added in row order, so
// the result does not depend on the threads.
float depthScale(const SampleBands& frame, int height) {
    const int rows = (height + kDepthScaleRowStep - 1) / kDepthScaleRowStep;
    std::vector<double> rowSums(std::size_t(rows), 0.0);
    std::vector<long long> rowCounts(std::size_t(rows), 0);
    const std::size_t rowValues = std::size_t(frame.width) * std::size_t(frame.spp) * kFeatureCount;
#pragma omp parallel for schedule(static)
    for (int r = 0; r < rows; ++r) {
        const float* row = frame.row(r * kDepthScaleRowStep);
        // Branch-free, four chains: a mispredicted test and one chain of dependent double adds
        // made this pass slower than reading the frame from memory.
        double sums[4] = {0.0, 0.0, 0.0, 0.0};
        long long counts[4] = {0, 0, 0, 0};
        std::size_t sample = 0;
        const std::size_t samples = rowValues / kFeatureCount;
        auto add = [&](int chain, float depth) {
            const bool hit = depth > 0.0f && depth <= 3.40282347e38f;  // false for NaN and +Inf
            sums[chain] += hit ? double(depth) : 0.0;
            counts[chain] += hit ? 1 : 0;
        };
        for (; sample + 4 <= samples; sample += 4)
            for (int chain = 0; chain < 4; ++chain)
                add(chain, row[(sample + std::size_t(chain)) * kFeatureCount + channel::kDepth]);
        for (; sample < samples; ++sample) add(0, row[sample * kFeatureCount + channel::kDepth]);
        rowSums[std::size_t(r)] = (sums[0] + sums[1]) + (sums[2] + sums[3]);
        rowCounts[std::size_t(r)] = (counts[0] + counts[1]) + (counts[2] + counts[3]);
    }
    double sum = 0.0;
    long long count = 0;
    for (int r = 0; r < rows; ++r) {
        sum += rowSums[std::size_t(r)];
        count += rowCounts[std::size_t(r)];
    }
    return count > 0 ? float(double(count) / sum) : 0.0f;
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

// Angle in degrees between two cameras' viewing directions, and the distance between them.
void cameraChange(const Matrix4& a, const Matrix4& b, double& degrees, double& distance) {
    // Row 2 of world-to-camera is the camera's +Z axis in world space; the position is
    // -R^T t.
    double dot = 0.0;
    for (int i = 0; i < 3; ++i) dot += double(a[8 + i]) * b[8 + i];
    degrees = std::acos(std::clamp(dot, -1.0, 1.0)) * 180.0 / 3.14159265358979;
    distance = 0.0;
    for (int i = 0; i < 3; ++i) {
        double pa = 0.0, pb = 0.0;
        for (int r = 0; r < 3; ++r) {
            pa -= double(a[r * 4 + i]) * a[r * 4 + 3];
            pb -= double(b[r * 4 + i]) * b[r * 4 + 3];
        }
        distance += (pa - pb) * (pa - pb);
    }
    distance = std::sqrt(distance);
}

// Milliseconds since `start`.
double millisecondsSince(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// Appends the time since the previous mark to a report's stage list.
class StageClock {
public:
    explicit StageClock(DenoiseReport& report) : report_(report) {}
    void mark(const char* stage) {
        report_.stageMilliseconds.emplace_back(stage, millisecondsSince(last_));
        last_ = std::chrono::steady_clock::now();
    }
    // Stages that ran interleaved (band by band), timed apart by the caller; restarts the clock.
    void add(const char* stage, double milliseconds) {
        report_.stageMilliseconds.emplace_back(stage, milliseconds);
        last_ = std::chrono::steady_clock::now();
    }

private:
    DenoiseReport& report_;
    std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

// What the U-Net's last full-resolution convolution reads: the coarser level read upsampled and
// the skip connection, or (in a decoder block of several convolutions) the previous output.
struct UnetTail {
    FeatureMap coarse;  // empty when the convolution reads `input` alone
    FeatureMap input;

    std::vector<ConvSource> sources() const {
        std::vector<ConvSource> list;
        if (!coarse.empty()) list.push_back({coarse.data(), coarse.channels(), true});
        list.push_back({input.data(), input.channels()});
        return list;
    }
};

// Rows of the kernel parameters made per band (band_schedule.h). Each thread transposes its
// rows' tap halo again per band, so bands much shorter cost time; at 1080p 4 spp (small model,
// streamed) 32/64/128/256/all rows gave a peak of 1331/1336/1310/1348/1627 MiB and equal time
// within this VM's noise.
constexpr int kBandRows = 128;

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

}  // namespace

struct Denoiser::State {
    Model model;
    DenoiserOptions options;
    bool hasHistory = false;
    // The previous frame's size, camera and mean depth, to tell when history cannot apply.
    int lastWidth = 0, lastHeight = 0;
    Matrix4 lastWorldToCamera{};
    float lastMeanDepth = 0.0f;
    // The sequence's exposure normalisation (exposure.h), 0 until a frame with light sets it.
    float exposure = 0.0f;
    // Temporal state (docs/MODEL.md sections 3 and 7): the accumulated signal and the last
    // kernel's output, in the filtered signal's channels (filter_signal.h).
    FeatureMap embeddingHistory, signalHistory, output, lastFeatures;
    // Every other map of a frame comes from the pool and goes back as soon as it is dead.
    FeatureMapPool pool;
    FeatureMap sampleSums;  // Embedding's per-pixel sums, until the signal is made from them
    FeatureMap signal;      // this frame's signal to accumulate, until it is
    // A frame arriving in batches (addSamples): sums kept until finishFrame(). Or a whole
    // frame's samples in a buffer lent with sampleBands().
    struct Pending {
        FeatureMap hiddenSum;  // from the pool
        std::vector<FeatureMap> lentBands;  // from the pool, (rows, width, spp x kFeatureCount) each
        int spp = 0, width = 0, height = 0;
        float depthScale = 0.0f;
        float exposure = 1.0f;
        long long invalidRadiance = 0;
        double milliseconds = 0.0;
    } pending;

    // Set while a call runs (Exclusive): concurrent calls on one sequence's state corrupted it.
    std::atomic<bool> busy{false};
    std::function<bool()> interruptCheck;

    State(Model m, DenoiserOptions o) : model(std::move(m)), options(o) {}
    // Throws Interrupted when the interrupt check asks to stop; called between steps, never
    // inside a parallel region.
    void checkInterrupt() const {
        if (interruptCheck && interruptCheck()) throw Interrupted("denoise: interrupted");
    }
    // A frame left half-done (interrupted, or failed) leaves histories that do not fit
    // together: the next frame starts a new sequence.
    template <typename Pipeline>
    std::vector<float> dropHistoryOnFailure(Pipeline&& pipeline) {
        try {
            return pipeline();
        } catch (...) {
            hasHistory = false;
            throw;
        }
    }
    // Whether a frame of this size, camera and mean depth can use the history (the caller checks
    // that there is one); if not, why (for DenoiseReport::resetReason).
    bool historyApplies(int width, int height, const FrameInfo& info, float meanDepth, std::string& reason) const;
    // The exposure for a frame's embedding: a new one from `samples` when the frame starts a
    // sequence or none was found yet (frames so far black), else the sequence's.
    float exposureFor(const SampleBands& samples, int height, bool startsSequence);
    // The U-Net up to the input of its last full-resolution convolution, which
    // parametersAndAccumulation() fuses with the head.
    UnetTail runUnet(const Network& net, const FeatureMap& embedding, const FeatureMap& historyEmbedding);
    // After the U-Net (docs/MODEL.md sections 3-7), band by band down the image: kernel
    // parameters, accumulation of `embedding` and `signal` into their (warped) histories with the
    // learned lambda, and the affinity kernels, whose output replaces `output`.
    void filterInBands(const Network& net, const UnetTail& tail, const FeatureMap& embedding,
                       FeatureMap& historyEmbedding, FeatureMap& historySignal, const float* motion,
                       const float* valid, bool history, StageClock& clock);
    KernelMaps takeKernelMaps(const Network& net, int height, int width, int ringRows);
    // Applies the convolutions of `block` in turn to `map`, each output replacing its input.
    void runBlock(const std::vector<Conv2d>& block, std::size_t first, std::size_t end, FeatureMap& map);
    // Rows [begin, end) of the kernel parameters, each pixel's accumulation done as soon as its
    // lambda is known, and the filtered part of the accumulated signal into `filterIn`.
    void parametersAndAccumulation(const Network& net, const UnetTail& tail, int begin, int end, KernelMaps& maps,
                                   const FeatureMap& embedding, FeatureMap& historyEmbedding,
                                   FeatureMap& historySignal, FeatureMap& filterIn);
    void give(KernelMaps& maps);
    // The signal to accumulate of a frame of `spp` samples from `sampleSums`, whose memory goes
    // back to the pool.
    void makeSignal(int spp);
    // The whole pipeline on a frame whose samples are all there (given, or lent by sampleBands()).
    // `lent`, if given, holds the maps behind `samples`, given back to the pool once embedded.
    std::vector<float> denoiseWholeFrame(const SampleBands& samples, int height, const float* motion,
                                         const float* valid, const FrameInfo& info, DenoiseReport* report,
                                         std::vector<FeatureMap>* lent = nullptr);
    // Everything after the embedding and the signal to accumulate (in `signal`): history, U-Net,
    // filters. `local` already holds the embedding stage.
    std::vector<float> denoiseEmbedded(FeatureMap embedding, float depthScale, const FrameInfo& info,
                                       const float* motion, const float* valid, DenoiseReport& local,
                                       StageClock& clock, DenoiseReport* report);
};

namespace {

// Holds a denoiser's state for one call; a second call at the same time is refused.
class Exclusive {
public:
    Exclusive(std::atomic<bool>& busy, const char* call) : busy_(busy) {
        if (busy_.exchange(true, std::memory_order_acquire))
            throw Error(std::string(call) +
                        ": the Denoiser is busy with another call (from another thread?): it holds one sequence's "
                        "state and takes one call at a time; give each thread its own Denoiser");
    }
    ~Exclusive() { busy_.store(false, std::memory_order_release); }
    Exclusive(const Exclusive&) = delete;
    Exclusive& operator=(const Exclusive&) = delete;

private:
    std::atomic<bool>& busy_;
};

}  // namespace

Denoiser::Denoiser(Model model, DenoiserOptions options)
    : state_(std::make_unique<State>(std::move(model), options)) {}
Denoiser::~Denoiser() = default;
Denoiser::Denoiser(Denoiser&&) noexcept = default;
Denoiser& Denoiser::operator=(Denoiser&&) noexcept = default;

const Model& Denoiser::model() const { return state_->model; }
const DenoiserOptions& Denoiser::options() const { return state_->options; }

void Denoiser::reset() {
    const Exclusive call(state_->busy, "reset");
    state_->hasHistory = false;
}

void Denoiser::setInterruptCheck(std::function<bool()> check) {
    const Exclusive call(state_->busy, "setInterruptCheck");
    state_->interruptCheck = std::move(check);
}

void Denoiser::State::runBlock(const std::vector<Conv2d>& block, std::size_t first, std::size_t end,
                              FeatureMap& map) {
    for (std::size_t j = first; j < end; ++j) {
        checkInterrupt();
        FeatureMap next = pool.take(map.height(), map.width(), block[j].outChannels());
        block[j].apply(map, Activation::LeakyRelu, next);
        pool.give(map);
        map = std::move(next);
    }
}

UnetTail Denoiser::State::runUnet(const Network& net, const FeatureMap& embedding,
                                  const FeatureMap& historyEmbedding) {
    const std::size_t levels = net.encoder.size();
    std::vector<FeatureMap> encoderOut(levels);  // the skip connections
    for (std::size_t level = 0; level < levels; ++level) {
        checkInterrupt();
        const std::vector<Conv2d>& block = net.encoder[level];
        FeatureMap& out = encoderOut[level];
        if (level == 0) {
            out = pool.take(embedding.height(), embedding.width(), block[0].outChannels());
            block[0].apply(embedding, historyEmbedding, Activation::LeakyRelu, out);
        } else {
            const FeatureMap& above = encoderOut[level - 1];
            FeatureMap pooled = pool.take((above.height() + 1) / 2, (above.width() + 1) / 2, above.channels());
            maxPool2x2(above, pooled);
            out = pool.take(pooled.height(), pooled.width(), block[0].outChannels());
            block[0].apply(pooled, Activation::LeakyRelu, out);
            pool.give(pooled);
        }
        runBlock(block, 1, block.size(), out);
    }
    const FeatureMap& deepest = encoderOut[levels - 1];
    FeatureMap low = pool.take((deepest.height() + 1) / 2, (deepest.width() + 1) / 2, deepest.channels());
    maxPool2x2(deepest, low);
    runBlock(net.bottleneck, 0, net.bottleneck.size(), low);
    // Decoder levels, the coarser level read upsampled; level 0 stops before its last convolution.
    for (std::size_t l = levels; l-- > 0;) {
        checkInterrupt();
        FeatureMap& skip = encoderOut[l];
        const std::vector<Conv2d>& block = net.decoder[l];
        if (l == 0 && block.size() == 1) return UnetTail{std::move(low), std::move(skip)};
        FeatureMap out = pool.take(skip.height(), skip.width(), block[0].outChannels());
        block[0].applyUpsampled(low, skip, Activation::LeakyRelu, out);
        pool.give(low);
        pool.give(skip);
        runBlock(block, 1, l == 0 ? block.size() - 1 : block.size(), out);
        low = std::move(out);
    }
    return UnetTail{FeatureMap(), std::move(low)};
}

KernelMaps Denoiser::State::takeKernelMaps(const Network& net, int height, int width, int ringRows) {
    KernelMaps maps;
    for (int k = 0; k < net.kernels; ++k) {
        maps.features.push_back(pool.take(k + 1 == net.kernels ? height : ringRows, width, net.affinityFeatures));
        maps.bandwidth.push_back(pool.take(ringRows, width, 1));
        maps.centre.push_back(pool.take(ringRows, width, 1));
    }
    maps.temporalBandwidth = pool.take(ringRows, width, 1);
    return maps;
}

// The last full-resolution convolution and the head, fused tile by tile so that neither
// full-resolution output exists as a whole: each tile's head output goes straight into the
// parameter maps (rings: row y at y % height), and its lambda into the accumulation.
void Denoiser::State::parametersAndAccumulation(const Network& net, const UnetTail& tail, int begin, int end,
                                                KernelMaps& maps, const FeatureMap& embedding,
                                                FeatureMap& historyEmbedding, FeatureMap& historySignal,
                                                FeatureMap& filterIn) {
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
    const int E = embedding.channels(), S = signal.channels(), C = filterIn.channels();
    if (C > S) throw Error("denoise: the filtered channels must be part of the accumulated signal");
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
                // per map and tile (per pixel, it made this stage 50-100 ms slower at 1080p).
                auto row = [y](FeatureMap& map) { return map.pixel(y % map.height(), 0); };
                for (std::size_t k = 0; k < std::size_t(K); ++k) {
                    float* features = row(maps.features[k]);
                    float* bandwidth = row(maps.bandwidth[k]);
                    float* centre = row(maps.centre[k]);
                    for (int x = x0; x < x1; ++x) {
                        const float* base = params.data() + std::size_t(x) * std::size_t(head.outChannels()) + int(k) * G;
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
                // kernels filter the first C channels of the accumulated signal (C <= S).
                // The filtered copy is stored from the same values: reading the just-stored floats
                // back as one wider load stalled on store forwarding (a third of this stage's time).
                float* filtered = row(filterIn);
                for (int x = x0; x < x1; ++x) {
                    const float l = lambda[std::size_t(x - x0)];
                    const float* e = embedding.pixel(y, x);
                    float* h = historyEmbedding.pixel(y, x);
                    for (int c = 0; c < E; ++c) h[c] = (1.0f - l) * e[c] + l * h[c];
                    const float* current = signal.pixel(y, x);
                    float* accumulated = historySignal.pixel(y, x);
                    float* f = filtered + std::size_t(x) * C;
                    for (int c = 0; c < C; ++c) f[c] = accumulated[c] = (1.0f - l) * current[c] + l * accumulated[c];
                    for (int c = C; c < S; ++c) accumulated[c] = (1.0f - l) * current[c] + l * accumulated[c];
                }
            }
        }
    }
}

void Denoiser::State::give(KernelMaps& maps) {
    for (std::vector<FeatureMap>* list : {&maps.features, &maps.bandwidth, &maps.centre})
        for (FeatureMap& map : *list) pool.give(map);
    pool.give(maps.temporalBandwidth);
}

void Denoiser::State::filterInBands(const Network& net, const UnetTail& tail, const FeatureMap& embedding,
                                    FeatureMap& historyEmbedding, FeatureMap& historySignal, const float* motion,
                                    const float* valid, bool history, StageClock& clock) {
    const int height = embedding.height(), width = embedding.width();
    const int K = net.kernels, F = net.affinityFeatures, C = net.signalLayout().filteredChannels();
    // The kernels that run, in order (all K, or the last alone), and how far their taps reach.
    std::vector<int> kernels, radii;
    for (int k = options.allKernels ? 0 : K - 1; k < K; ++k) {
        kernels.push_back(k);
        radii.push_back((net.tapSize / 2) << k);
    }
    const bool temporal = history && options.temporalKernel;
    const int ringRows = bandRingRows(height, kBandRows, radii);
    KernelMaps params = takeKernelMaps(net, height, width, ringRows);
    FeatureMap filterIn = pool.take(ringRows, width, C);
    std::vector<FeatureMap> between;  // the output of each kernel but the last
    for (std::size_t i = 0; i + 1 < kernels.size(); ++i) between.push_back(pool.take(ringRows, width, C));
    FeatureMap newOutput = pool.take(height, width, C);
    FeatureMap warpedOutput, warpedFeatures, warpedValid;  // the temporal taps' rows
    if (temporal) {
        warpedOutput = pool.take(ringRows, width, C);
        warpedFeatures = pool.take(ringRows, width, F);
        warpedValid = pool.take(ringRows, width, 1);
    }
    int warpedEnd = 0;
    const TemporalTaps taps{&params.temporalBandwidth, &warpedOutput, &warpedFeatures, &warpedValid};

    double parameterMs = 0.0, spatialMs = 0.0, temporalMs = 0.0;
    for (const BandStep& step : bandSchedule(height, kBandRows, radii)) {
        checkInterrupt();
        auto start = std::chrono::steady_clock::now();
        parametersAndAccumulation(net, tail, step.begin, step.end, params, embedding, historyEmbedding, historySignal,
                                  filterIn);
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
                for (int y = warpedEnd; y < warpTo; ++y)
                    std::copy(valid + std::size_t(y) * width, valid + std::size_t(y + 1) * width,
                              warpedValid.pixel(y % ringRows, 0));
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
    pool.give(newOutput);
    pool.give(lastFeatures);
    lastFeatures = std::move(params.features[std::size_t(K - 1)]);
    give(params);
    for (FeatureMap* map : {&filterIn, &warpedOutput, &warpedFeatures, &warpedValid}) pool.give(*map);
    for (FeatureMap& map : between) pool.give(map);
}

bool Denoiser::State::historyApplies(int width, int height, const FrameInfo& info, float meanDepth,
                                     std::string& reason) const {
    double degrees = 0.0, distance = 0.0;
    cameraChange(lastWorldToCamera, info.worldToCamera, degrees, distance);
    if (width != lastWidth || height != lastHeight)
        reason = "frame size changed";
    else if (degrees > 45.0)
        reason = "camera turned by " + std::to_string(int(degrees)) + " degrees";
    else if (meanDepth > 0.0f && distance > 0.5 * std::max(meanDepth, lastMeanDepth))
        reason = "camera moved by more than half the scene depth";
    else
        return true;
    return false;
}

float Denoiser::State::exposureFor(const SampleBands& samples, int height, bool startsSequence) {
    if (startsSequence || exposure <= 0.0f) exposure = exposureOf(samples, height);
    return exposure > 0.0f ? exposure : 1.0f;
}

std::vector<float> Denoiser::denoise(const SampleFrame& frame, DenoiseReport* report) {
    return denoise(frame.view("denoise"), report);
}

std::vector<float> Denoiser::denoise(const SampleFrameView& frame, DenoiseReport* report) {
    State& s = *state_;
    const Exclusive call(s.busy, "denoise");
    if (frame.width < 1 || frame.height < 1 || frame.spp < 1) throw Error("denoise: the frame is empty");
    if (!frame.samples || !frame.motion || !frame.valid) throw Error("denoise: the frame lacks a buffer");
    if (s.pending.spp > 0)
        throw Error("denoise: " + std::to_string(s.pending.spp) +
                    " samples added with addSamples() or lent with sampleBands() wait for finishFrame() (or "
                    "discardSamples())");

    s.pool.setKeepRatio(FeatureMapPool::kKeepRatio);
    return s.dropHistoryOnFailure([&] {
        return s.denoiseWholeFrame(SampleBands(frame.samples, frame.height, frame.width, frame.spp), frame.height,
                                   frame.motion, frame.valid, frame.info, report);
    });
}

std::vector<float> Denoiser::State::denoiseWholeFrame(const SampleBands& samples, int height, const float* motion,
                                                      const float* valid, const FrameInfo& info,
                                                      DenoiseReport* report, std::vector<FeatureMap>* lent) {
    const Network& net = model.network();
    DenoiseReport local;
    StageClock clock(local);
    // 1-2. Per-sample embedding averaged per pixel; the signal to accumulate and filter.
    const float depth = depthScale(samples, height);
    std::string ignored;
    // The sequence goes on (also in single-frame mode, which keeps the sequence's exposure).
    const bool continues =
        hasHistory && historyApplies(samples.width, height, info, depth > 0.0f ? 1.0f / depth : 0.0f, ignored);
    const InputScales scales(depth, exposureFor(samples, height, !continues));
    local.exposure = scales.exposure;
    FeatureMap embedding = pool.take(height, samples.width, net.embedding->outChannels());
    // The signal straight from each chunk's sample sums: a map of the sums would be the third
    // largest while the samples are held.
    const SignalLayout layout = net.signalLayout();
    signal = pool.take(height, samples.width, layout.channels());
    const int spp = samples.spp, channels = layout.channels();
    local.invalidRadiance = net.embedding->apply(
        samples, height, scales, embedding, [&](long long firstPixel, int count, const float* sums) {
            signalFromSums(sums, count, spp, layout, signal.data() + std::size_t(firstPixel) * std::size_t(channels));
        });
    if (lent)
        for (FeatureMap& band : *lent) pool.give(band);  // read: their memory serves the later stages
    clock.mark("embedding");
    return denoiseEmbedded(std::move(embedding), depth, info, motion, valid, local, clock, report);
}

std::vector<SampleBand> Denoiser::sampleBands(int width, int height, int spp) {
    State& s = *state_;
    const Exclusive call(s.busy, "sampleBands");
    State::Pending& p = s.pending;
    if (width < 1 || height < 1 || spp < 1) throw Error("sampleBands: the frame is empty");
    if (spp > SampleFrame::kMaxSpp)
        throw Error("sampleBands: " + std::to_string(spp) + " samples per pixel, at most " +
                    std::to_string(SampleFrame::kMaxSpp));
    if (p.spp > 0)
        throw Error("sampleBands: " + std::to_string(p.spp) + " samples wait for finishFrame() (or discardSamples())");
    // The bands are large maps among smaller ones: a free band serving a small map would leave
    // the next frame's bands to new memory. Measured at 1080p, 4 spp (bench_denoiser --lend 1),
    // peak RSS with the pool keeping maps over 2x / 3x / 6x the request for later: tiny 1290 /
    // 1230 / 1290 MiB, small 1439 / 1550 / 1605, medium 1567 / 1487 / 1673.
    s.pool.setKeepRatio(kLentKeepRatio);
    // A band holds no more floats than a full-resolution embedding map, the largest maps made
    // after the embedding, so that those can take the bands' memory.
    const int channels = spp * kFeatureCount;
    const int bandRows =
        int(std::clamp<long long>((long long)height * s.model.network().embedding->outChannels() / channels, 1, height));
    std::vector<SampleBand> bands;
    for (int row = 0; row < height; row += bandRows) {
        const int rows = std::min(bandRows, height - row);
        p.lentBands.push_back(s.pool.take(rows, width, channels));
        bands.push_back({row, rows, p.lentBands.back().data()});
    }
    p.width = width;
    p.height = height;
    p.spp = spp;
    return bands;
}

void Denoiser::addSamples(int width, int height, int spp, const float* samples) {
    State& s = *state_;
    const Exclusive call(s.busy, "addSamples");
    const auto start = std::chrono::steady_clock::now();
    if (width < 1 || height < 1 || spp < 1) throw Error("addSamples: the batch is empty");
    if (!samples) throw Error("addSamples: the batch has no samples buffer");
    State::Pending& p = s.pending;
    if (!p.lentBands.empty())
        throw Error("addSamples: a frame lent with sampleBands() waits for finishFrame() (or discardSamples())");
    const bool first = p.spp == 0;
    if (!first && (width != p.width || height != p.height))
        throw Error("addSamples: a " + std::to_string(width) + "x" + std::to_string(height) +
                    " batch does not match the frame's first batch of " + std::to_string(p.width) + "x" +
                    std::to_string(p.height));
    const Network& net = s.model.network();
    if (first) {
        s.pool.setKeepRatio(FeatureMapPool::kKeepRatio);
        p.width = width;
        p.height = height;
        const SampleBands batch(samples, height, width, spp);
        p.depthScale = depthScale(batch, height);
        // A camera cut shows only at finishFrame(): such a frame keeps the exposure before it.
        const bool continues = s.hasHistory && width == s.lastWidth && height == s.lastHeight;
        p.exposure = s.exposureFor(batch, height, !continues);
        p.invalidRadiance = 0;
        p.milliseconds = 0.0;
        p.hiddenSum = s.pool.take(height, width, net.embedding->hiddenChannels());
        s.sampleSums = s.pool.take(height, width, Embedding::kSampleSumChannels);
    }
    p.invalidRadiance +=
        net.embedding->accumulate(samples, height, width, spp, InputScales(p.depthScale, p.exposure), p.hiddenSum,
                                  first, &s.sampleSums);
    p.spp += spp;
    p.milliseconds += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

std::vector<float> Denoiser::finishFrame(const float* motion, const float* valid, const FrameInfo& info,
                                         DenoiseReport* report) {
    State& s = *state_;
    const Exclusive call(s.busy, "finishFrame");
    State::Pending& p = s.pending;
    if (p.spp == 0) throw Error("finishFrame: no samples were added with addSamples() or lent with sampleBands()");
    if (!motion || !valid) throw Error("finishFrame: the frame lacks a motion or validity buffer");
    if (!p.lentBands.empty()) {
        // Taken out of the pending state first: after a failure here nothing waits any more.
        std::vector<FeatureMap> bands = std::move(p.lentBands);
        p.lentBands.clear();
        p.spp = 0;
        SampleBands samples;
        for (const FeatureMap& band : bands) samples.bands.push_back(band.data());
        samples.bandRows = bands.front().height();
        samples.width = p.width;
        samples.spp = bands.front().channels() / kFeatureCount;
        return s.dropHistoryOnFailure(
            [&] { return s.denoiseWholeFrame(samples, p.height, motion, valid, info, report, &bands); });
    }
    const Network& net = s.model.network();
    DenoiseReport local;
    StageClock clock(local);
    // In place where the last layer keeps the width: the sums and the embedding, together with
    // the previous frame's embedding, would otherwise be the largest set of maps alive.
    FeatureMap embedding;
    if (net.embedding->outChannels() == net.embedding->hiddenChannels()) {
        embedding = std::move(p.hiddenSum);
        net.embedding->finish(embedding, p.spp, embedding);
    } else {
        embedding = s.pool.take(p.height, p.width, net.embedding->outChannels());
        net.embedding->finish(p.hiddenSum, p.spp, embedding);
        s.pool.give(p.hiddenSum);
    }
    s.makeSignal(p.spp);
    local.invalidRadiance = p.invalidRadiance;
    local.exposure = p.exposure;
    const float depth = p.depthScale;
    const double addMilliseconds = p.milliseconds;
    p.spp = 0;
    clock.mark("embedding");
    local.stageMilliseconds.back().second += addMilliseconds;  // the batches' share of the stage
    return s.dropHistoryOnFailure(
        [&] { return s.denoiseEmbedded(std::move(embedding), depth, info, motion, valid, local, clock, report); });
}

void Denoiser::discardSamples() {
    const Exclusive call(state_->busy, "discardSamples");
    state_->pending.spp = 0;
    for (FeatureMap& band : state_->pending.lentBands) state_->pool.give(band);
    state_->pending.lentBands.clear();
    state_->pool.give(state_->pending.hiddenSum);
    state_->pool.give(state_->sampleSums);
}

void Denoiser::State::makeSignal(int spp) {
    const SignalLayout layout = model.network().signalLayout();
    signal = pool.take(sampleSums.height(), sampleSums.width(), layout.channels());
    makeAccumulatedSignal(sampleSums, spp, layout, signal);
    pool.give(sampleSums);
}

Denoiser::PendingFrame Denoiser::pending() const {
    const State::Pending& p = state_->pending;
    return p.spp > 0 ? PendingFrame{p.width, p.height, p.spp} : PendingFrame{};
}

std::vector<float> Denoiser::State::denoiseEmbedded(FeatureMap embedding, float depthScale, const FrameInfo& info,
                                                    const float* motion, const float* valid, DenoiseReport& local,
                                                    StageClock& clock, DenoiseReport* report) {
    State& s = *this;
    const Network& net = s.model.network();
    const int width = embedding.width(), height = embedding.height();
    // Drop history where it cannot apply.
    const float meanDepth = depthScale > 0.0f ? 1.0f / depthScale : 0.0f;
    if (s.hasHistory && !s.historyApplies(width, height, info, meanDepth, local.resetReason)) s.hasHistory = false;
    s.lastWidth = width;
    s.lastHeight = height;
    s.lastWorldToCamera = info.worldToCamera;
    s.lastMeanDepth = meanDepth;
    if (!s.options.useHistory) s.hasHistory = false;
    const bool history = s.hasHistory;
    local.usedHistory = history;
    const int E = embedding.channels();

    // 3. Histories: warped previous state where valid, the current frame elsewhere.
    FeatureMap historyEmbedding = s.pool.take(height, width, E);
    FeatureMap historySignal = s.pool.take(height, width, s.signal.channels());
    if (history) {
        // Radiance sharp (a blurred history blurs the output), embeddings bilinear (cheaper).
        warpBilinear(s.embeddingHistory, motion, historyEmbedding);
        warpCatmullRom(s.signalHistory, motion, historySignal);
        keepWhereValid(historyEmbedding, embedding, valid);
        keepWhereValid(historySignal, s.signal, valid);
    } else {
        historyEmbedding = embedding;
        historySignal = s.signal;
    }
    s.pool.give(s.embeddingHistory);  // read: their memory serves the U-Net
    s.pool.give(s.signalHistory);
    clock.mark("warp history");
    s.checkInterrupt();

    // 4-7. U-Net, then the kernel parameters, accumulation and kernels band by band.
    UnetTail tail = s.runUnet(net, embedding, historyEmbedding);
    clock.mark("u-net");
    s.filterInBands(net, tail, embedding, historyEmbedding, historySignal, motion, valid, history, clock);
    s.pool.give(tail.coarse);
    s.pool.give(tail.input);
    s.pool.give(embedding);
    s.pool.give(s.signal);
    s.embeddingHistory = std::move(historyEmbedding);
    s.signalHistory = std::move(historySignal);
    s.hasHistory = true;

    std::vector<float> radiance(std::size_t(width) * std::size_t(height) * 3);
    radianceFromSignal(s.output, s.signalHistory, net.signalLayout(), radiance.data());
    local.bufferBytes = s.pool.heldCapacity() * sizeof(float);
    if (report) *report = local;
    return radiance;
}

}  // namespace affinity
