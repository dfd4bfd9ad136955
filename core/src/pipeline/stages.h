#pragma once
// The stages of docs/MODEL.md after the embedding, for one frame: the sequence's history warped
// into the frame (section 3), the U-Net (section 4), then band by band down the image the kernel
// parameters (section 5), the accumulation with the learned lambda (section 3) and the affinity
// kernels (sections 6-7). Every map comes from the frame's pool and goes back to it once dead.
#include <chrono>
#include <functional>
#include <vector>

#include "affinity/denoiser.h"
#include "kernels/feature_map.h"
#include "network/network.h"
#include "pipeline/feature_map_pool.h"
#include "pipeline/sequence_history.h"

namespace affinity {

// Milliseconds since `start`.
inline double millisecondsSince(std::chrono::steady_clock::time_point start) {
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

// The caller's interrupt check (Denoiser::setInterruptCheck), asked between steps, never inside a
// parallel region: throws affinity::Interrupted when it returns true. Empty: never interrupted.
struct InterruptCheck {
    std::function<bool()> check;
    void operator()() const;
};

// The accumulated embedding and signal of this frame: the history warped into it, then (by
// filterInBands) the frame's own mixed in with the learned lambda.
struct Accumulated {
    FeatureMap embedding, signal;
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

// Which of the kernels run (all as trained, unless an ablation switched some off).
struct KernelChoice {
    bool temporal = true;      // the last kernel's taps into the previous output (needs history)
    bool allKernels = true;    // false: the last (widest) kernel alone
    bool historyGuard = true;  // the temporal taps' bright-history guard (history_guard.h)
};

struct KernelMaps;

class Stages {
public:
    Stages(const Network& net, FeatureMapPool& pool, const InterruptCheck& interrupted)
        : net_(net), pool_(pool), interrupted_(interrupted) {}

    // 3. The history's accumulated maps warped into the frame by `motion` where `valid` says the
    // history holds, the frame's own `embedding` and `signal` elsewhere (everywhere without
    // `history`). The history's maps are read: their memory goes back to the pool.
    Accumulated warpHistory(const FeatureMap& embedding, const FeatureMap& signal, SequenceHistory& sequence,
                            bool history, const float* motion, const float* valid);
    // 4. The U-Net up to the input of its last full-resolution convolution, which filterInBands()
    // fuses with the head.
    UnetTail unet(const FeatureMap& embedding, const FeatureMap& historyEmbedding);
    // 5-7. Band by band down the image: kernel parameters, accumulation of `embedding` and
    // `signal` into `accumulated` with the learned lambda, and the affinity kernels, the temporal
    // one reading the sequence's last output and features, which this frame's then replace.
    void filterInBands(const UnetTail& tail, const FeatureMap& embedding, const FeatureMap& signal,
                       Accumulated& accumulated, const float* motion, const float* valid, KernelChoice choice,
                       SequenceHistory& sequence, StageClock& clock);
    void give(UnetTail& tail);

private:
    // Applies the convolutions [first, end) of `block` in turn to `map`, each output replacing its input.
    void runBlock(const std::vector<Conv2d>& block, std::size_t first, std::size_t end, FeatureMap& map);
    KernelMaps takeKernelMaps(int height, int width, int ringRows);
    void give(KernelMaps& maps);
    // Rows [begin, end) of the kernel parameters, each pixel's accumulation done as soon as its
    // lambda is known, and a copy of the accumulated signal into `filterIn`.
    void parametersAndAccumulation(const UnetTail& tail, int begin, int end, KernelMaps& maps,
                                   const FeatureMap& embedding, const FeatureMap& signal, Accumulated& accumulated,
                                   FeatureMap& filterIn);

    const Network& net_;
    FeatureMapPool& pool_;
    const InterruptCheck& interrupted_;
};

}  // namespace affinity
