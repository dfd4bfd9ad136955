#pragma once
// The training loss of ALGORITHM.md section 7 over one sequence of frames:
//   Loss = SMAPE(O, O*) + 0.25 SMAPE(dt O, dt O*) + 1e-5 (sum_k E[(a^k)^2] + E[b^2])
//   SMAPE(A, B) = mean over pixels and channels of |A - B| / (|A| + |B| + 0.01)
// where dt is the difference between consecutive frames. Optional terms (LossWeights: absolute
// temporal, coarse) are off in the paper's loss. Plain ATen ops: autograd provides the
// gradients (tests/cpp/test_training.cpp checks them against finite differences).
#include <vector>

#include <ATen/core/Tensor.h>

namespace affinity::train {

inline constexpr double kSmapeEpsilon = 0.01;
inline constexpr double kTemporalWeight = 0.25;
inline constexpr double kRegulariserWeight = 1e-5;

// mean |a - b| / (|a| + |b| + 0.01) over every element.
at::Tensor smapeLoss(const at::Tensor& image, const at::Tensor& reference);

// [B, C, H, W] -> [B, C, ceil(H / cell), ceil(W / cell)]: the mean of each cell x cell block, a
// partial block at the bottom or right edge averaged over the pixels it has.
at::Tensor cellMeans(const at::Tensor& image, int cell);

// Weights of the temporal terms; the defaults are the paper's loss. The absolute temporal term is
//   mean |dt O - dt O*| / (mean |O*| + 0.01)   (means per crop, over pixels and channels)
// the benchmark's temporal error (ALGORITHM.md section 10) per unit of the crop's brightness.
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
struct LossWeights {
    double temporal = kTemporalWeight;
    double absoluteTemporal = 0;
    bool warpedTemporal = false;
    double coarse = 0;
    int coarseCell = 8;
};

// Frame t's motion [B, 2, H, W] (pixels into frame t-1) and history validity [B, 1, H, W].
struct FrameMotion {
    at::Tensor motion;
    at::Tensor valid;
};

struct LossTerms {
    at::Tensor total;             // scalar, differentiable
    at::Tensor spatial;           // SMAPE(O, O*) averaged over frames
    at::Tensor temporal;          // SMAPE(dt O, dt O*) averaged over frame pairs (0 for one frame)
    at::Tensor absoluteTemporal;  // the absolute temporal term averaged over frame pairs
    at::Tensor coarse;            // SMAPE of the cell means averaged over frames
    at::Tensor regulariser;  // sum_k E[(a^k)^2] + E[b^2], averaged over frames
};

// outputs[t], references[t]: [B, 3, H, W]. bandwidths[t]: the K bandwidths a^k and the temporal
// bandwidth b of frame t, each [B, 1, H, W] (empty vectors skip the regulariser). motions: one
// per frame, needed only with weights.warpedTemporal.
LossTerms sequenceLoss(const std::vector<at::Tensor>& outputs, const std::vector<at::Tensor>& references,
                       const std::vector<std::vector<at::Tensor>>& bandwidths, const LossWeights& weights = {},
                       const std::vector<FrameMotion>& motions = {});

}  // namespace affinity::train
