#pragma once
// The differentiable building blocks of docs/MODEL.md in ATen ops: input sanitising, bilinear
// warping, pooling and upsampling of the U-Net, and the dilated / temporal affinity kernels.
// Every image tensor is [B, C, H, W] in the dtype of its inputs; autograd works through all.
#include <ATen/core/Tensor.h>

namespace affinity::train {

// The per-sample network input (section 1) and the noisy radiance L_t of a batch of frames.
struct PreparedInputs {
    at::Tensor networkInput;  // [B, S, 18, H, W]
    at::Tensor radiance;      // [B, 3, H, W]: mean over samples of the sanitised radiance
    at::Tensor invalidCount;  // [B] int64: radiance values that were non-finite or negative
    at::Tensor exposure;      // [B]: the exposure the radiance was scaled by (0: black, scaled by 1)
};
// samples: [B, S, 18, H, W] raw features. depthScale is computed per batch element (frame), the
// exposure normalisation too unless `exposure` ([B], a sequence's) is given; where that is 0 (the
// sequence's frames so far black) it is computed from this frame.
PreparedInputs prepareInputs(const at::Tensor& samples, const at::Tensor& exposure = at::Tensor());
// The core's exposureOf (core/src/pipeline/exposure.h) per batch element of sanitised radiance
// [B, S, 6, H, W] (diffuse then specular, non-finite and negative values already 0): [B] in double.
at::Tensor exposureOf(const at::Tensor& cleanRadiance);

// out(p) = bilinear lookup of `previous` at (x + motion_x, y + motion_y), pixel centres at
// integer coordinates, taps outside the image clamped to the border. motion: [B, 2, H, W]
// (non-finite motion reads as 0). Gradients flow to `previous` and to `motion`.
at::Tensor warpBilinear(const at::Tensor& previous, const at::Tensor& motion);

// out(p) = Catmull-Rom lookup (4x4 taps) of `previous` at (x + motion_x, y + motion_y), the
// position clamped to the image and the taps to its border, then clamped channel by channel to
// the range of the four nearest taps (docs/MODEL.md section 3): the sharp warp of the signal
// history and the previous output. Gradients flow to `previous`; motion is data.
at::Tensor warpCatmullRom(const at::Tensor& previous, const at::Tensor& motion);

// The two warps above in ATen ops (gathers), on any device and with gradients to motion:
// what runs where the fused CPU ops of fused_warps.h do not, and their test reference.
at::Tensor warpBilinearUnfused(const at::Tensor& previous, const at::Tensor& motion);
at::Tensor warpCatmullRomUnfused(const at::Tensor& previous, const at::Tensor& motion);

// Where warpBilinear looks in the previous frame, before clamping: x + motion_x and y + motion_y,
// each [B, H, W] (non-finite motion reads as 0).
struct WarpTargets {
    at::Tensor x, y;
};
WarpTargets warpTargets(const at::Tensor& motion);

// 2x2 max pooling, ceil mode: an odd edge keeps its last row/column.
at::Tensor maxPool2x2(const at::Tensor& input);
// out(y, x) = in(y / 2, x / 2) (integer division) for an output of height x width.
at::Tensor upsampleNearest(const at::Tensor& input, std::int64_t height, std::int64_t width);

// Per-pixel parameters of one affinity kernel (section 5): features [B, F, H, W], bandwidth a
// [B, 1, H, W] and centre weight c [B, 1, H, W] (already through its sigmoid).
struct KernelParams {
    at::Tensor features;
    at::Tensor bandwidth;
    at::Tensor centre;
};

// The taps on the previous frame for the last kernel (section 7), all already warped:
// output Ô [B, C, H, W] (in the filtered signal's channels), features ĝ [B, F, H, W], validity v̂ [B, 1, H, W]; bandwidth b
// [B, 1, H, W] is the current frame's.
struct TemporalTaps {
    at::Tensor bandwidth;
    at::Tensor output;
    at::Tensor features;
    at::Tensor valid;
};

inline constexpr double kAffinityEpsilon = 1e-8;

// One dilated spatial kernel (section 6) on a signal [B, C, H, W] (C = 3 or 6): tapSize x tapSize taps at
// the given dilation, out-of-image taps skipped. On the CPU the fused op of
// fused_affinity_filter.h, elsewhere affinityFilterUnfused.
at::Tensor affinityFilter(const at::Tensor& radiance, const KernelParams& kernel, int tapSize, int dilation);
// The last kernel (section 7): the spatial taps plus 3x3 temporal taps in one normalised sum.
at::Tensor affinityFilterTemporal(const at::Tensor& radiance, const KernelParams& kernel, int tapSize, int dilation,
                                  const TemporalTaps& temporal);
// The same kernels in ATen ops (about ten per tap) on any device, with temporal taps where
// `temporal` is given: what runs off the CPU, and what the fused op is tested against.
at::Tensor affinityFilterUnfused(const at::Tensor& radiance, const KernelParams& kernel, int tapSize, int dilation,
                                 const TemporalTaps* temporal);

}  // namespace affinity::train
