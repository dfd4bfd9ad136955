#pragma once
// Renders an animation frame by frame into SampleFrames: S separate samples per pixel, a
// converged reference, and motion vectors with a validity mask from the primary hits.
#include <cstdint>
#include <functional>
#include <memory>

#include "affinity/frame.h"
#include "render/embree_scene.h"
#include "render/path_tracer.h"
#include "render/scene.h"

namespace affinity::render {

struct RenderSettings {
    int width = 256;
    int height = 256;
    int spp = 4;
    int referenceSpp = 1024;  // 0: no reference
    std::uint64_t seed = 0;
    int maxBounces = 16;
    // Which vertices the features describe; the reference (radiance only) is the same either way.
    FeatureConvention featureConvention = FeatureConvention::Renderer;
};

// Called with the fraction of the frame done, from one thread at a time.
using ProgressCallback = std::function<void(double)>;

class SequenceRenderer {
public:
    // Throws affinity::Error for invalid settings or an invalid scene.
    SequenceRenderer(const Scene& scene, const RenderSettings& settings);
    ~SequenceRenderer();

    // Frames must be rendered in increasing order; frame t has valid history only when frame
    // t - 1 was the previous frame rendered by this renderer. `stop`, asked before each row on
    // one thread, abandons the frame when it returns true: render() then throws
    // affinity::Interrupted (for Ctrl-C; a frame can take minutes).
    SampleFrame render(int frameIndex, const ProgressCallback& progress = {}, const std::function<bool()>& stop = {});

    // Rays cast so far (camera, bounce and shadow rays), for throughput figures.
    std::uint64_t raysCast() const { return raysCast_; }

private:
    void computeMotion(int frameIndex, const EmbreeScene& current, SampleFrame& frame) const;

    const Scene& scene_;
    RenderSettings settings_;
    std::unique_ptr<EmbreeScene> previous_;
    int previousIndex_ = -1;
    std::uint64_t raysCast_ = 0;
};

// Deterministic random stream of sample `sampleIndex` of a pixel: independent of threads.
// Reference samples use indices from kReferenceStream on, so they never repeat a noisy sample.
inline constexpr std::uint64_t kReferenceStream = 1ull << 32;

}  // namespace affinity::render
