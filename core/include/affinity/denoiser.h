#pragma once
// The stateful sequence denoiser: feed a sequence's frames in order, get denoised linear RGB
// back. It keeps the temporal state (accumulated embeddings and radiance, previous output
// and affinity features) between calls; reset() forgets it, as at a camera cut. Single-frame
// use is the same call on a fresh (or reset) denoiser. Being one sequence's state, it takes one
// call at a time: a call made while another runs (from another thread) throws affinity::Error;
// separate denoisers run side by side.
#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "affinity/frame.h"
#include "affinity/model.h"

namespace affinity {

struct DenoiseReport {
    long long invalidRadiance = 0;  // NaN, Inf, negative or > kMaxRadiance values treated as 0
    bool usedHistory = false;       // a previous frame contributed
    std::string resetReason;        // why history was dropped before this frame, if it was
    // The sequence's exposure normalisation (docs/MODEL.md section 1): the factor on the radiance
    // the network saw, set at the first frame of a sequence (1 while every frame was black).
    float exposure = 1.0f;
    // Wall-clock milliseconds per pipeline stage, in pipeline order, for profiling.
    std::vector<std::pair<std::string, double>> stageMilliseconds;
    // Bytes of the buffers the denoiser keeps after the frame (all its maps, in use or free for
    // the next frame): its memory between frames, and at the peak of one but for transients.
    std::size_t bufferBytes = 0;
};

struct Ablation;  // core/src/pipeline/ablation.h: internal, for the benchmark

class Denoiser {
public:
    explicit Denoiser(Model model = Model::builtIn());
    ~Denoiser();
    Denoiser(Denoiser&&) noexcept;
    Denoiser& operator=(Denoiser&&) noexcept;

    // Denoises the next frame of the sequence. Returns height x width x 3 linear radiance.
    // History is dropped automatically when the frame size changes or the camera jumps.
    std::vector<float> denoise(const SampleFrame& frame, DenoiseReport* report = nullptr);
    // The same on buffers the caller owns (nothing is copied).
    std::vector<float> denoise(const SampleFrameView& frame, DenoiseReport* report = nullptr);
    // Streaming input, for callers that make a frame's samples a few at a time (Blender renders
    // one sample per sub-render), so that the per-sample features are never held whole:
    // addSamples() for each batch of the frame's samples in order ([y][x][s][feature] with spp
    // samples per pixel), then finishFrame() with the frame's motion ([y][x][2]), validity
    // ([y][x]) and camera. Bit for bit what denoise() gives on the concatenated samples, except
    // that the depth normalisation (docs/MODEL.md section 1) comes from the first batch alone.
    // reset() does not touch samples added so far; discardSamples() drops them (as after a
    // cancelled render). Throws affinity::Error on an empty batch, a batch of another size than
    // the frame's first, finishFrame() without samples, or denoise() while samples wait.
    void addSamples(int width, int height, int spp, const float* samples);
    std::vector<float> finishFrame(const float* motion, const float* valid, const FrameInfo& info,
                                   DenoiseReport* report = nullptr);
    void discardSamples();
    // Lent input, for callers that make a whole frame's samples at once (a file reader): memory
    // of the denoiser's own for width x height x spp samples, in bands of whole rows, each band
    // [row][x][s][feature]; the caller fills every band, then finishFrame() denoises them, bit
    // for bit what denoise() gives on the same samples. Once the embedding has read the bands,
    // their memory serves the later stages (bands are about the size of those stages' largest
    // maps, so they can), and the samples add little to a frame's peak memory (the "lent" rows
    // of results/speed_1080p_intel.md against the others). The bands are
    // the denoiser's again at finishFrame() or discardSamples() (which drops them); contents
    // start undefined. Throws affinity::Error, as addSamples() does, while other samples wait.
    std::vector<SampleBand> sampleBands(int width, int height, int spp);
    // The frame being streamed or lent: its size, and the samples added since the last
    // finishFrame() or lent for it (0 when none).
    struct PendingFrame {
        int width = 0, height = 0, spp = 0;
    };
    PendingFrame pending() const;

    void reset();
    // Whether a frame of this size seen from this camera would carry the history on, asked
    // before any of its samples exist: false without a history, after a size change, or where
    // the camera jumped as at a cut (turned by more than 45 degrees, or moved by more than half
    // the last frame's mean depth: the rule by which denoise() drops the history, the frame's own
    // depth unknown here). The Blender extension pre-rolls a frame that would not.
    bool continuesSequence(int width, int height, const Matrix4& worldToCamera) const;

    // Called on the calling thread between the steps of a frame (each convolution, each band of
    // the kernels; at 1080p the longest step takes tens of milliseconds): when it returns true,
    // the frame is abandoned, the call throws affinity::Interrupted, and the next frame starts a
    // new sequence as after reset(). For Ctrl-C in the CLI and Python. Empty: never interrupted.
    void setInterruptCheck(std::function<bool()> check);

    const Model& model() const;

private:
    friend Denoiser ablatedDenoiser(Model model, const Ablation& ablation);
    struct State;
    std::unique_ptr<State> state_;
};

}  // namespace affinity
