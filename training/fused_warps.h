#pragma once
// The bilinear and Catmull-Rom warps of affinity_ops.h as CPU autograd ops whose backward
// scatters straight into the previous frame's gradient, plane by plane, instead of through
// ATen's gather / scatter_add and minimum / maximum backward (a fifth of a training step). The
// same functions as the ATen forms, which run on other devices, where motion needs a gradient,
// and in the tests as the reference. Gradients flow to `previous` only: motion is data.
#include <ATen/core/Tensor.h>

namespace affinity::train {

// Whether the fused warps take these tensors: float or double on the CPU, motion without grad.
bool fusedWarpApplies(const at::Tensor& previous, const at::Tensor& motion);

at::Tensor fusedWarpBilinear(const at::Tensor& previous, const at::Tensor& motion);
at::Tensor fusedWarpCatmullRom(const at::Tensor& previous, const at::Tensor& motion);

}  // namespace affinity::train
