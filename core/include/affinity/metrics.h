#pragma once
// Image error metrics on linear RGB buffers of equal size (n floats). Definitions follow
// docs/METHOD.md section 10; Python: affinity_core.metrics.
#include <cstddef>

namespace affinity {

// mean |a - b| / (|a| + |b| + 0.01) over pixels and channels.
double smape(const float* image, const float* reference, std::size_t n);
// 0.5 * mean (a - b)^2 / (b^2 + 0.01).
double relativeMse(const float* image, const float* reference, std::size_t n);
// PSNR in dB after tone mapping both with x / (1 + x) (values in [0, 1)).
double tonemappedPsnr(const float* image, const float* reference, std::size_t n);

// Temporal error (flicker relative to the reference's own change) of frame t against frame t-1:
// mean over valid pixels and the 3 channels of |(O_t - W O_{t-1}) - (R_t - W R_{t-1})|, where W
// warps the previous frame bilinearly by `motion` (height x width x 2, pixels into the previous
// frame, frame layout). A pixel (x, y) counts when valid >= 0.5 and its warp target lies inside
// the grid of pixel centres, x + motion.x in [0, width-1] and y + motion.y in [0, height-1], so
// no tap is border-clamped. Images are height x width x 3; NaN when no pixel counts.
double temporalError(const float* output, const float* previousOutput, const float* reference,
                     const float* previousReference, const float* motion, const float* valid, int width, int height);

// Warping error of Lai et al. 2018 ("Learning Blind Video Temporal Consistency"), the flicker of
// an image sequence on its own, without a reference: mean over the pixels that temporalError
// counts of || T(I_t) - W T(I_{t-1}) ||^2, the squared difference summed over the 3 channels,
// where T is the tone map of tonemappedPsnr (negatives clamped to 0, then x / (1 + x)) and W the
// same bilinear warp by `motion`. Real changes of the scene count too, so a sequence's reference
// has a warping error of its own: the value a perfect output would have. NaN when no pixel counts.
double warpingError(const float* image, const float* previousImage, const float* motion, const float* valid, int width,
                    int height);

}  // namespace affinity
