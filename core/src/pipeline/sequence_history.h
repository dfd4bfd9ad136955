#pragma once
// What a Denoiser carries from one frame of a sequence to the next: the accumulated embedding and
// signal and the last kernel's output and features (docs/MODEL.md sections 3 and 7), the
// sequence's exposure (section 1), and the previous frame's size, camera and depth, by which a
// frame that cannot use the history (a camera cut) is told.
#include <string>

#include "affinity/frame.h"
#include "kernels/feature_map.h"
#include "network/embedding.h"
#include "pipeline/light_restoration.h"

namespace affinity {

class SequenceHistory {
public:
    // The temporal maps, valid while has(): the accumulated embedding and signal (the radiance,
    // filter_signal.h) and the last kernel's output (the denoised radiance) and features. The
    // stages read them and put the frame's own in their place.
    FeatureMap embedding, signal, output, lastFeatures;
    // The light restoration's accumulations (light_restoration.h) and the input fallback's
    // accumulated noise (input_fallback.h).
    LightHistory light;
    FeatureMap fallbackNoise;

    bool has() const { return has_; }
    // Forgets the sequence (reset(), a failed or interrupted frame): the next frame starts a new one.
    void drop() { has_ = false; }
    // Whether a frame of this size, camera and mean depth (0: nothing hit) continues the sequence.
    bool continuedBy(int width, int height, const FrameInfo& info, float meanDepth) const;
    // The same asked before the frame's samples exist: its mean depth unknown, the last frame's
    // stands for it.
    bool continuedByCamera(int width, int height, const FrameInfo& info) const;
    // The same known from the size alone (a streamed frame's first batch, before its camera).
    bool continuedBySize(int width, int height) const;
    // Starts a frame: drops the history where the frame cannot use it (saying why in
    // `resetReason`), or always when `useHistory` is false, and remembers the frame's size,
    // camera and mean depth for the next. Returns whether the frame uses the history.
    bool startFrame(int width, int height, const FrameInfo& info, float meanDepth, bool useHistory,
                    std::string& resetReason);
    // After a frame: its accumulated maps are the history.
    void keep(FeatureMap&& accumulatedEmbedding, FeatureMap&& accumulatedSignal);

    // The exposure for a frame's embedding (exposure.h): a new one from `samples` when the frame
    // starts a sequence or none was found yet (frames so far black), else the sequence's.
    float exposureFor(const SampleBands& samples, int height, bool startsSequence);

private:
    // Whether a frame of this size, camera and mean depth can use the history (the caller checks
    // that there is one); if not, why.
    bool applies(int width, int height, const FrameInfo& info, float meanDepth, std::string& reason) const;

    bool has_ = false;
    int lastWidth_ = 0, lastHeight_ = 0;
    Matrix4 lastWorldToCamera_{};
    float lastMeanDepth_ = 0.0f;
    float exposure_ = 0.0f;  // 0 until a frame with light sets it
};

}  // namespace affinity
