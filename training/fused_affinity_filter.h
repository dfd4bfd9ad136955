#pragma once
// The dilated and temporal affinity kernels (docs/MODEL.md sections 6-7) as one autograd op on
// CPU tensors: a forward and a hand-written backward in loops over rows, instead of about ten
// ATen ops per tap (81 taps a frame), each with its own allocation, thread wake-up and saved
// intermediate. The same function as the ATen form in affinity_ops.cpp, which runs on other
// devices and which the tests check this against (values and gradients).
#include "affinity_ops.h"

namespace affinity::train {

// Whether fusedAffinityFilter takes these tensors: float or double, on the CPU.
bool fusedAffinityFilterApplies(const at::Tensor& radiance);

// out(p) = (c r(p) + sum_q w(p, q) r(q) + sum_t w_t(p, t) O(t)) / (c + sum_q w + sum_t w_t + eps):
// the spatial taps q of a tapSize x tapSize grid at `dilation`, and with `temporal` the 3x3
// taps t on the warped previous output. Gradients flow to every input but the validity.
at::Tensor fusedAffinityFilter(const at::Tensor& radiance, const KernelParams& kernel, int tapSize, int dilation,
                               const TemporalTaps* temporal);

}  // namespace affinity::train
