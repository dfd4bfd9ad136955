#pragma once
// The weights of the training loss's terms (train_loss.h), torch-free so that the trainer's
// options (trainer.h) can hold them.

namespace affinity::train {

inline constexpr double kTemporalWeight = 0.25;

// Weights of the loss terms; the defaults are the paper's loss. Every term here is part of the
// shipped recipe (docs/TRAINING.md): the warped temporal terms, the absolute temporal term in the
// last stage, the coarse term. The absolute temporal term is
//   mean |dt O - dt O*| / (mean |O*| + 0.01)   (means per crop, over pixels and channels)
// the benchmark's temporal error (docs/METHOD.md section 10) per unit of the crop's brightness.
// SMAPE of dt O weighs a flickering lamp like a flickering shadow; the benchmark, and the eye in a
// tone-mapped frame, weigh flicker by its size, so this term lets bright pixels count as much.
// With warpedTemporal, dt O is O_t - W O_{t-1} (W: the previous frame warped by frame t's motion,
// as the benchmark's temporal error does), counted only where the history is valid and the warp
// lands inside the crop: the change a still camera would see, so the term measures flicker and
// not the image moving.
//
// The coarse term is SMAPE(C O, C O*), C the mean over cells of coarseCell x coarseCell pixels
// (partial cells at the crop's edge averaged over their pixels). Pixel SMAPE is minimised by the
// median of what the input allows, and against a noisy (Noise2Noise) target by the median of
// that target: where radiance is heavy-tailed (caustics, small lights seen through glossy
// bounces) the median lies below the mean and the output comes out dark. A cell's mean averages
// coarseCell^2 pixels of the target, so its median is close to its mean: the term asks the filter
// to spread a rare bright sample's energy over its neighbourhood rather than drop it.
//
// The displayed term is mean |D(O) - D(O*)|, D(x) = (x / (1 + x) + e)^(1/2.2) - e^(1/2.2) with
// x clamped at 0 and e = kDisplayedEpsilon: the error of the images as the benchmark shows them to
// ColorVideoVDP (tone-mapped by x / (1 + x), gamma 1/2.2; e keeps the gradient finite at black).
// SMAPE weighs a relative error in a dark corner as much as one on a lit wall; on a display, and
// to the eye, the dark error is far smaller.
//
// firstFrame weighs the image terms (SMAPE, coarse, displayed) of a sequence's first frame against the
// others' 1: that frame has no history, as every frame after a camera cut, and is the frame a
// temporal denoiser does worst. The reported spatial and coarse terms stay the plain means over
// frames, so that runs with different weights compare.
struct LossWeights {
    double temporal = kTemporalWeight;
    double absoluteTemporal = 0;
    bool warpedTemporal = false;
    double coarse = 0;
    int coarseCell = 8;
    double firstFrame = 1;
    double displayed = 0;
};

inline constexpr double kDisplayedEpsilon = 1e-3;

}  // namespace affinity::train
