#pragma once
// The training loss of ALGORITHM.md section 7 over one sequence of frames:
//   Loss = SMAPE(O, O*) + 0.25 SMAPE(dt O, dt O*) + 1e-5 (sum_k E[(a^k)^2] + E[b^2])
//   SMAPE(A, B) = mean over pixels and channels of |A - B| / (|A| + |B| + 0.01)
// where dt is the difference between consecutive frames. Plain ATen ops: autograd provides the
// gradients (tests/cpp/test_training.cpp checks them against finite differences).
#include <vector>

#include <ATen/core/Tensor.h>

namespace affinity::train {

inline constexpr double kSmapeEpsilon = 0.01;
inline constexpr double kTemporalWeight = 0.25;
inline constexpr double kRegulariserWeight = 1e-5;

// mean |a - b| / (|a| + |b| + 0.01) over every element.
at::Tensor smapeLoss(const at::Tensor& image, const at::Tensor& reference);

struct LossTerms {
    at::Tensor total;        // scalar, differentiable
    at::Tensor spatial;      // SMAPE(O, O*) averaged over frames
    at::Tensor temporal;     // SMAPE(dt O, dt O*) averaged over frame pairs (0 for one frame)
    at::Tensor regulariser;  // sum_k E[(a^k)^2] + E[b^2], averaged over frames
};

// outputs[t], references[t]: [B, 3, H, W]. bandwidths[t]: the K bandwidths a^k and the temporal
// bandwidth b of frame t, each [B, 1, H, W] (empty vectors skip the regulariser).
LossTerms sequenceLoss(const std::vector<at::Tensor>& outputs, const std::vector<at::Tensor>& references,
                       const std::vector<std::vector<at::Tensor>>& bandwidths);

}  // namespace affinity::train
