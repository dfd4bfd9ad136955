#pragma once
// How a frame's samples reach the Denoiser (affinity/denoiser.h), and the stage every way ends in:
// the embedding and the signal to accumulate (docs/MODEL.md sections 1-2). A frame comes whole
// (denoise()), streamed in batches (addSamples(), then finishFrame()) or written by the caller
// into bands the denoiser lends (sampleBands(), then finishFrame()); a streamed or lent frame
// waits here between the calls.
#include <vector>

#include "affinity/denoiser.h"
#include "affinity/frame.h"
#include "kernels/feature_map.h"
#include "network/embedding.h"
#include "network/network.h"
#include "pipeline/feature_map_pool.h"
#include "pipeline/sequence_history.h"

namespace affinity {

// A frame after its first stage: what the later stages read.
struct EmbeddedFrame {
    FeatureMap embedding;      // per pixel, docs/MODEL.md section 2 (from the pool)
    FeatureMap signal;         // to accumulate and filter, filter_signal.h (from the pool)
    FeatureMap meanSquares;    // the mean squared luminance of the samples, filter_signal.h (pool)
    FeatureMap emissiveShare;  // the share of the samples that saw an emitter, filter_signal.h (pool)
    int spp = 0;               // samples per pixel
    float depthScale = 0.0f;   // 1 / the mean depth of the samples that hit something; 0: none did
    float exposure = 1.0f;     // the factor on the radiance the network saw
    long long invalidRadiance = 0;
    double batchMilliseconds = 0.0;  // spent on the batches (addSamples) before the frame's last call

    float meanDepth() const { return depthScale > 0.0f ? 1.0f / depthScale : 0.0f; }
};

// The embedding and signal of a frame whose samples are all there (given, or lent and written),
// its exposure that of `history`'s sequence if the frame continues it.
EmbeddedFrame embedWholeFrame(const Network& net, FeatureMapPool& pool, SequenceHistory& history,
                              const SampleBands& samples, int height, const FrameInfo& info);

// The frame being streamed or lent, between the Denoiser's calls. Each call's checks throw
// affinity::Error naming the Denoiser's call.
class FrameInput {
public:
    // The frame's size and its samples added or lent so far (zero when none wait).
    Denoiser::PendingFrame pending() const;
    // For denoise(), which takes a whole frame: throws while samples wait.
    void refuseWhileWaiting(const char* call) const;

    // sampleBands(): memory of the pool's for width x height x spp samples, in bands of rows.
    std::vector<SampleBand> lend(const Network& net, FeatureMapPool& pool, int width, int height, int spp);
    // addSamples(): one batch through the embedding's layers but its last, into per-pixel sums.
    // The first batch sets the frame's depth scale and exposure (from `history`).
    void add(const Network& net, FeatureMapPool& pool, SequenceHistory& history, int width, int height, int spp,
             const float* samples);

    // finishFrame(), a lent frame: its bands, taken out of the waiting state (after a failure
    // from here on nothing waits any more), and the samples in them.
    struct LentFrame {
        std::vector<FeatureMap> bands;
        SampleBands samples;
        int height = 0;
    };
    bool lent() const { return !lentBands_.empty(); }
    LentFrame takeLent();
    // finishFrame(), a streamed frame: the embedding and signal from the batches' sums.
    EmbeddedFrame finishStreamed(const Network& net, FeatureMapPool& pool);

    // discardSamples(): whatever waits goes back to the pool.
    void discard(FeatureMapPool& pool);

private:
    FeatureMap hiddenSum_;               // streamed: the embedding's hidden layer summed (pool)
    FeatureMap sampleSums_;              // streamed: Embedding's per-pixel sample sums (pool)
    std::vector<FeatureMap> lentBands_;  // lent: (rows, width, spp x kFeatureCount) each (pool)
    int spp_ = 0, width_ = 0, height_ = 0;
    float depthScale_ = 0.0f;
    float exposure_ = 1.0f;
    long long invalidRadiance_ = 0;
    double milliseconds_ = 0.0;
};

}  // namespace affinity
