// The Denoiser's API and the per-frame pipeline of docs/MODEL.md, stage by stage: embedding ->
// warp the history -> U-Net -> band by band: kernel parameters and accumulation, dilated affinity
// kernels, temporal kernel -> radiance. What each stage does is in frame_input.h (the embedding,
// for the three ways a frame's samples arrive), stages.h (the rest) and sequence_history.h (what
// carries from frame to frame).
#include "affinity/denoiser.h"

#include <atomic>
#include <string>
#include <utility>

#include "affinity/error.h"
#include "network/filter_signal.h"
#include "network/network.h"
#include "pipeline/ablation.h"
#include "pipeline/feature_map_pool.h"
#include "pipeline/frame_input.h"
#include "pipeline/input_fallback.h"
#include "pipeline/light_restoration.h"
#include "pipeline/peak_guard.h"
#include "pipeline/sequence_history.h"
#include "pipeline/stages.h"

namespace affinity {

struct Denoiser::State {
    Model model;
    Ablation ablation;  // ablation.h: all on but for the benchmark's ablations
    SequenceHistory history;
    FrameInput input;
    // Every map of a frame but the history's comes from the pool and goes back as soon as it is
    // dead, so that the same memory serves every frame.
    FeatureMapPool pool;

    // Set while a call runs (Exclusive): concurrent calls on one sequence's state corrupted it.
    std::atomic<bool> busy{false};
    InterruptCheck interrupted;

    explicit State(Model m) : model(std::move(m)) {}
    // A frame left half-done (interrupted, or failed) leaves histories that do not fit
    // together: the next frame starts a new sequence.
    template <typename Pipeline>
    std::vector<float> dropHistoryOnFailure(Pipeline&& pipeline) {
        try {
            return pipeline();
        } catch (...) {
            history.drop();
            throw;
        }
    }
    // The whole pipeline on a frame whose samples are all there (given, or lent by sampleBands()).
    // `lent`, if given, holds the maps behind `samples`, given back to the pool once embedded.
    std::vector<float> denoiseWholeFrame(const SampleBands& samples, int height, const float* motion,
                                         const float* valid, const FrameInfo& info, DenoiseReport* report,
                                         std::vector<FeatureMap>* lent = nullptr);
    // Everything after the embedding: history, U-Net, filters. `local` already holds the
    // embedding stage.
    std::vector<float> denoiseEmbedded(EmbeddedFrame frame, const FrameInfo& info, const float* motion,
                                       const float* valid, DenoiseReport& local, StageClock& clock,
                                       DenoiseReport* report);
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

Denoiser::Denoiser(Model model) : state_(std::make_unique<State>(std::move(model))) {}
Denoiser::~Denoiser() = default;
Denoiser::Denoiser(Denoiser&&) noexcept = default;
Denoiser& Denoiser::operator=(Denoiser&&) noexcept = default;

Denoiser ablatedDenoiser(Model model, const Ablation& ablation) {
    Denoiser denoiser(std::move(model));
    denoiser.state_->ablation = ablation;
    return denoiser;
}

const Model& Denoiser::model() const { return state_->model; }

void Denoiser::reset() {
    const Exclusive call(state_->busy, "reset");
    state_->history.drop();
}

bool Denoiser::continuesSequence(int width, int height, const Matrix4& worldToCamera) const {
    const Exclusive call(state_->busy, "continuesSequence");
    FrameInfo info;
    info.worldToCamera = worldToCamera;
    return state_->history.continuedByCamera(width, height, info);
}

void Denoiser::setInterruptCheck(std::function<bool()> check) {
    const Exclusive call(state_->busy, "setInterruptCheck");
    state_->interrupted.check = std::move(check);
}

// ---- a whole frame: denoise() ----

std::vector<float> Denoiser::denoise(const SampleFrame& frame, DenoiseReport* report) {
    return denoise(frame.view("denoise"), report);
}

std::vector<float> Denoiser::denoise(const SampleFrameView& frame, DenoiseReport* report) {
    State& s = *state_;
    const Exclusive call(s.busy, "denoise");
    if (frame.width < 1 || frame.height < 1 || frame.spp < 1) throw Error("denoise: the frame is empty");
    if (!frame.samples || !frame.motion || !frame.valid) throw Error("denoise: the frame lacks a buffer");
    s.input.refuseWhileWaiting("denoise");

    s.pool.setKeepRatio(FeatureMapPool::kKeepRatio);
    return s.dropHistoryOnFailure([&] {
        return s.denoiseWholeFrame(SampleBands(frame.samples, frame.height, frame.width, frame.spp), frame.height,
                                   frame.motion, frame.valid, frame.info, report);
    });
}

// ---- a frame streamed or lent: addSamples() or sampleBands(), then finishFrame() ----

std::vector<SampleBand> Denoiser::sampleBands(int width, int height, int spp) {
    State& s = *state_;
    const Exclusive call(s.busy, "sampleBands");
    return s.input.lend(s.model.network(), s.pool, width, height, spp);
}

void Denoiser::addSamples(int width, int height, int spp, const float* samples) {
    State& s = *state_;
    const Exclusive call(s.busy, "addSamples");
    s.input.add(s.model.network(), s.pool, s.history, width, height, spp, samples);
}

std::vector<float> Denoiser::finishFrame(const float* motion, const float* valid, const FrameInfo& info,
                                         DenoiseReport* report) {
    State& s = *state_;
    const Exclusive call(s.busy, "finishFrame");
    if (s.input.pending().spp == 0)
        throw Error("finishFrame: no samples were added with addSamples() or lent with sampleBands()");
    if (!motion || !valid) throw Error("finishFrame: the frame lacks a motion or validity buffer");
    if (s.input.lent()) {
        FrameInput::LentFrame lent = s.input.takeLent();
        return s.dropHistoryOnFailure(
            [&] { return s.denoiseWholeFrame(lent.samples, lent.height, motion, valid, info, report, &lent.bands); });
    }
    DenoiseReport local;
    StageClock clock(local);
    EmbeddedFrame frame = s.input.finishStreamed(s.model.network(), s.pool);
    clock.mark("embedding");
    local.stageMilliseconds.back().second += frame.batchMilliseconds;  // the batches' share of the stage
    return s.dropHistoryOnFailure(
        [&] { return s.denoiseEmbedded(std::move(frame), info, motion, valid, local, clock, report); });
}

void Denoiser::discardSamples() {
    const Exclusive call(state_->busy, "discardSamples");
    state_->input.discard(state_->pool);
}

Denoiser::PendingFrame Denoiser::pending() const { return state_->input.pending(); }

// ---- the pipeline ----

std::vector<float> Denoiser::State::denoiseWholeFrame(const SampleBands& samples, int height, const float* motion,
                                                      const float* valid, const FrameInfo& info, DenoiseReport* report,
                                                      std::vector<FeatureMap>* lent) {
    DenoiseReport local;
    StageClock clock(local);
    // 1-2. Per-sample embedding averaged per pixel; the signal to accumulate and filter.
    EmbeddedFrame frame = embedWholeFrame(model.network(), pool, history, samples, height, info);
    if (lent)
        for (FeatureMap& band : *lent) pool.give(band);  // read: their memory serves the later stages
    clock.mark("embedding");
    return denoiseEmbedded(std::move(frame), info, motion, valid, local, clock, report);
}

std::vector<float> Denoiser::State::denoiseEmbedded(EmbeddedFrame frame, const FrameInfo& info, const float* motion,
                                                    const float* valid, DenoiseReport& local, StageClock& clock,
                                                    DenoiseReport* report) {
    const Network& net = model.network();
    const int width = frame.embedding.width(), height = frame.embedding.height();
    local.exposure = frame.exposure;
    local.invalidRadiance = frame.invalidRadiance;
    // The history where it can apply (not across a cut, a size change, or with it switched off).
    const bool useHistory =
        history.startFrame(width, height, info, frame.meanDepth(), ablation.useHistory, local.resetReason);
    local.usedHistory = useHistory;
    Stages stages(net, pool, interrupted);

    // 3. Histories: warped previous state where valid, the current frame elsewhere.
    Accumulated accumulated = stages.warpHistory(frame.embedding, frame.signal, history, useHistory, motion, valid);
    clock.mark("warp history");
    interrupted();
    // 4. U-Net.
    UnetTail tail = stages.unet(frame.embedding, accumulated.embedding);
    clock.mark("u-net");
    // 5-7. Kernel parameters, accumulation and kernels, band by band.
    const KernelChoice kernels{useHistory && ablation.temporalKernel, ablation.allKernels, ablation.historyGuard};
    stages.filterInBands(tail, frame.embedding, frame.signal, accumulated, motion, valid, kernels, history, clock);
    stages.give(tail);
    pool.give(frame.embedding);
    history.keep(std::move(accumulated.embedding), std::move(accumulated.signal));

    // The last kernel's output is the radiance (and stays the temporal kernel's history as it is).
    const float* output = history.output.data();
    std::vector<float> radiance(output, output + std::size_t(width) * std::size_t(height) * kSignalChannels);
    if (ablation.peakGuard) {
        guardPeaks(frame.signal, frame.meanSquares, frame.emissiveShare, frame.spp, radiance.data(), pool);
        clock.mark("peak guard");
    }
    if (net.lightRestoration && ablation.lightRestoration) {
        restoreLight(frame.signal, motion, valid, useHistory, history.light, radiance.data(), pool);
        clock.mark("light restoration");
    }
    if (ablation.inputFallback) {
        fallBackToInput(frame.signal, frame.meanSquares, frame.spp, motion, valid, useHistory, history.fallbackNoise,
                        radiance.data(), pool);
        clock.mark("input fallback");
    }
    pool.give(frame.meanSquares);
    pool.give(frame.emissiveShare);
    pool.give(frame.signal);
    local.bufferBytes = pool.heldCapacity() * sizeof(float);
    if (report) *report = local;
    return radiance;
}

}  // namespace affinity
