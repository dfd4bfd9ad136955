#pragma once
// The training loss of docs/METHOD.md section 7 over one sequence of frames:
//   Loss = SMAPE(O, O*) + 0.25 SMAPE(dt O, dt O*) + 1e-5 (sum_k E[(a^k)^2] + E[b^2])
//   SMAPE(A, B) = mean over pixels and channels of |A - B| / (|A| + |B| + 0.01)
// where dt is the difference between consecutive frames. Optional terms (LossWeights: absolute
// temporal, coarse) are off in the paper's loss. Plain ATen ops: autograd provides the gradients
// (tests/cpp/test_training.cpp checks them against finite differences).
#include <vector>

#include <ATen/core/Tensor.h>

#include "loss_weights.h"

namespace affinity::train {

inline constexpr double kSmapeEpsilon = 0.01;
inline constexpr double kRegulariserWeight = 1e-5;

// mean |a - b| / (|a| + |b| + 0.01) over every element.
at::Tensor smapeLoss(const at::Tensor& image, const at::Tensor& reference);

// D(x) of the displayed term (loss_weights.h), elementwise.
at::Tensor displayedImage(const at::Tensor& image);

// [B, C, H, W] -> [B, C, ceil(H / cell), ceil(W / cell)]: the mean of each cell x cell block, a
// partial block at the bottom or right edge averaged over the pixels it has.
at::Tensor cellMeans(const at::Tensor& image, int cell);

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
    at::Tensor displayed;         // mean |D(O) - D(O*)| averaged over frames (loss_weights.h)
    at::Tensor regulariser;       // sum_k E[(a^k)^2] + E[b^2], averaged over frames
};

// outputs[t], references[t]: [B, 3, H, W]. bandwidths[t]: the K bandwidths a^k and the temporal
// bandwidth b of frame t, each [B, 1, H, W] (empty vectors skip the regulariser). motions: one
// per frame, needed only with weights.warpedTemporal.
LossTerms sequenceLoss(const std::vector<at::Tensor>& outputs, const std::vector<at::Tensor>& references,
                       const std::vector<std::vector<at::Tensor>>& bandwidths, const LossWeights& weights = {},
                       const std::vector<FrameMotion>& motions = {});

}  // namespace affinity::train
