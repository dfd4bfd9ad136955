#pragma once
// The weights of the training loss's terms (train_loss.h), torch-free so that the trainer's
// options (trainer.h) can hold them.

namespace affinity::train {

inline constexpr double kTemporalWeight = 0.25;

// Weights of the loss terms; the defaults are the paper's loss. The absolute temporal term is
//   mean |dt O - dt O*| / (mean |O*| + 0.01)   (means per crop, over pixels and channels)
// the benchmark's temporal error (docs/METHOD.md section 10) per unit of the crop's brightness.
// SMAPE of dt O weighs a flickering lamp like a flickering shadow; the benchmark, and the eye in a
// tone-mapped frame, weigh flicker by its size, so this term lets bright pixels count as much.
// With warpedTemporal, dt O is O_t - W O_{t-1} (W: the previous frame warped by frame t's motion,
// as the benchmark's temporal error does), counted only where the history is valid and the warp
// lands inside the crop: the change a still camera would see, so the term measures flicker and
// not the image moving.
//
// With boundedAbsoluteTemporal each pixel's |dt O - dt O*| is divided by its own reference
// brightness plus the crop's mean, per channel:
//   mean ( |dt O - dt O*| / (|O*| + mean |O*| + 0.01) )
// The plain form lets one pixel own the term: a spark thousands of times brighter than its
// crop, whose value the few samples of a frame cannot pin down, flickers by more than the rest
// of the crop together, and a model trained on it learns to smear the spark's light over its
// neighbours, where it then flickers less per pixel (a halo: docs/TRAINING.md, "Sparks in the
// training data"). Bounded, a pixel's share is at most its relative change, while flicker in
// the crop's ordinary and dark pixels still counts by its size against the crop's brightness.
//
// The absolute spatial term is the same measure of the image itself, per crop:
//   mean |O - O*| / (mean |O*| + 0.01)
// It balances the absolute temporal term. A spark's flicker can be lowered by averaging it over
// time (what the term is for) or by smearing its light over its neighbours (a halo: docs/
// TRAINING.md, "Sparks in the training data"). SMAPE barely sees the halo, since a pixel's SMAPE
// is at most 1 however much light it wrongly holds; this term charges the moved light by its size,
// on the same scale as the flicker it saves, so only the temporal route stays cheap.
//
// The coarse term is SMAPE(C O, C O*), C the mean over cells of coarseCell x coarseCell pixels
// (partial cells at the crop's edge averaged over their pixels). Pixel SMAPE is minimised by the
// median of what the input allows, and against a noisy (Noise2Noise) target by the median of
// that target: where radiance is heavy-tailed (caustics, small lights seen through glossy
// bounces) the median lies below the mean and the output comes out dark. A cell's mean averages
// coarseCell^2 pixels of the target, so its median is close to its mean: the term asks the filter
// to spread a rare bright sample's energy over its neighbourhood rather than drop it.
struct LossWeights {
    double temporal = kTemporalWeight;
    double absoluteTemporal = 0;
    bool warpedTemporal = false;
    double coarse = 0;
    int coarseCell = 8;
    bool boundedAbsoluteTemporal = false;
    double absoluteSpatial = 0;
};

}  // namespace affinity::train
