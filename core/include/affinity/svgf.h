#pragma once
// SVGF, Schied et al. 2017, "Spatiotemporal Variance-Guided Filtering: Real-Time
// Reconstruction for Path-Traced Global Illumination": the hand-designed real-time baseline
// our denoiser is compared with (docs/METHOD.md section 9). Stateful like affinity::Denoiser:
// feed a sequence's frames in order; reset() forgets the history, as at a camera cut.
//
// Per frame: the noisy radiance (mean of the samples' diffuse + specular) is demodulated by
// the albedo; colour and the first two luminance moments are reprojected from the previous
// frame (bilinear taps, each tested for depth and normal consistency) and accumulated with an
// exponential moving average; the luminance variance comes from the temporal moments, or from
// a 7x7 bilateral estimate where fewer than 4 frames of history exist; five iterations of the
// 5x5 a-trous wavelet filter with edge-stopping functions on depth, normals and variance-
// normalised luminance follow; the result is remodulated by the albedo. The first iteration's
// output is the colour history for the next frame. The radiance of emissive samples (lamps,
// the sky) bypasses the filter and is added back at the end, as the paper's implementation
// does with emission. Guides per pixel: the mean over the non-emissive samples of the finite
// positive depths and of the normals (normalised).
#include <memory>
#include <vector>

#include "affinity/frame.h"

namespace affinity {

// Defaults are the paper's (section 4 and 5).
struct SvgfSettings {
    int atrousIterations = 5;       // a-trous passes with step sizes 1, 2, 4, ...; 0 to 10
    int feedbackIteration = 0;      // the output of this pass is the next frame's colour history
    float sigmaDepth = 1.0f;        // sigma_z: depth difference relative to the depth gradient
    float sigmaNormal = 128.0f;     // sigma_n: exponent on max(0, n(p) . n(q))
    float sigmaLuminance = 4.0f;    // sigma_l: luminance difference in standard deviations
    float alphaColor = 0.2f;        // EMA weight of the new frame's colour, in (0, 1]
    float alphaMoments = 0.2f;      // EMA weight of the new frame's luminance moments, in (0, 1]
    int historyCap = 32;            // history length is counted up to this many frames
    int spatialVarianceFrames = 4;  // below this history length, variance is estimated spatially
    // Reprojection consistency tests for each bilinear tap into the previous frame: the tap's
    // depth may differ from the pixel's by reprojectDepthTolerance times (its screen-space depth
    // gradient + 0.2 % of its depth), and the normals must satisfy n(p) . n(tap) >= this cosine.
    float reprojectDepthTolerance = 10.0f;
    float reprojectNormalCosine = 0.9f;
    // Radiance is demodulated by max(albedo, albedoEpsilon) per channel and remodulated by the
    // same factor, so black surfaces round-trip exactly.
    float albedoEpsilon = 1e-3f;
};

class Svgf {
public:
    // Throws affinity::Error for settings outside the ranges documented above.
    explicit Svgf(SvgfSettings settings = {});
    ~Svgf();
    Svgf(Svgf&&) noexcept;
    Svgf& operator=(Svgf&&) noexcept;

    // Filters the next frame of the sequence. Returns height x width x 3 linear radiance.
    // NaN, Inf and negative radiance read as 0. History is dropped automatically when the
    // frame size changes; pixels whose `valid` is 0 (or whose reprojection fails the depth and
    // normal tests) start a new history. Throws affinity::Error for an empty or inconsistent
    // frame.
    std::vector<float> denoise(const SampleFrame& frame);
    // The same on buffers the caller owns (nothing is copied).
    std::vector<float> denoise(const SampleFrameView& frame);
    void reset();

    const SvgfSettings& settings() const;
    // Per pixel, the number of frames accumulated so far (1 after a disocclusion, at most
    // historyCap): height x width after the last denoise(), empty before it or after reset().
    std::vector<float> historyLength() const;

private:
    struct State;
    std::unique_ptr<State> state_;
};

}  // namespace affinity
