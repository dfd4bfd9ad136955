#include "affinity_ops.h"

#include <ATen/ATen.h>
#include <array>

#include <cstdlib>
#include <limits>
#include <string>

#include "affinity/error.h"
#include "affinity/features.h"
#include "fused_affinity_filter.h"
#include "fused_warps.h"

namespace affinity::train {
namespace {

// A normalised sum under construction: Σ w v and Σ w.
struct WeightedSum {
    at::Tensor numerator;
    at::Tensor denominator;
};

// The (H, W) window of a zero-padded tensor shifted by (dy, dx) from its centre.
at::Tensor shifted(const at::Tensor& padded, std::int64_t pad, std::int64_t dy, std::int64_t dx, std::int64_t height,
                   std::int64_t width) {
    return padded.narrow(2, pad + dy, height).narrow(3, pad + dx, width);
}

at::Tensor squaredDistance(const at::Tensor& a, const at::Tensor& b) { return (a - b).square().sum(1, true); }

// Section 6's taps. Out-of-image taps read zero-padded values and a zero `inside` mask, so they
// add nothing to either sum (and nothing to any gradient).
WeightedSum spatialSum(const at::Tensor& radiance, const KernelParams& kernel, int tapSize, int dilation) {
    if (tapSize < 1 || tapSize % 2 == 0)
        throw Error("affinity filter: tap size " + std::to_string(tapSize) + " is not odd");
    const std::int64_t height = radiance.size(2), width = radiance.size(3);
    const std::int64_t radius = (tapSize - 1) / 2;
    const std::int64_t pad = radius * dilation;
    const std::vector<std::int64_t> padding{pad, pad, pad, pad};
    const at::Tensor paddedRadiance = at::constant_pad_nd(radiance, padding, 0);
    const at::Tensor paddedFeatures = at::constant_pad_nd(kernel.features, padding, 0);
    // Out-of-image taps weigh 0.
    const at::Tensor inside = at::constant_pad_nd(at::ones_like(kernel.bandwidth), padding, 0);
    const at::Tensor negativeA2 = -(kernel.bandwidth * kernel.bandwidth);

    WeightedSum sum{kernel.centre * radiance, kernel.centre};
    for (std::int64_t i = -radius; i <= radius; ++i) {
        for (std::int64_t j = -radius; j <= radius; ++j) {
            const std::int64_t dy = i * dilation, dx = j * dilation;
            if (i == 0 && j == 0) continue;
            if (std::abs(dy) >= height || std::abs(dx) >= width) continue;  // wholly outside
            const at::Tensor neighbour = shifted(paddedFeatures, pad, dy, dx, height, width);
            const at::Tensor weight = at::exp(negativeA2 * squaredDistance(kernel.features, neighbour)) *
                                      shifted(inside, pad, dy, dx, height, width);
            sum.numerator = sum.numerator + weight * shifted(paddedRadiance, pad, dy, dx, height, width);
            sum.denominator = sum.denominator + weight;
        }
    }
    return sum;
}

void checkImage(const at::Tensor& tensor, const char* what, std::int64_t channels) {
    if (tensor.dim() != 4 || (channels > 0 && tensor.size(1) != channels)) {
        throw Error(std::string("affinity ops: ") + what + " must be [B, " +
                    (channels > 0 ? std::to_string(channels) : std::string("C")) + ", H, W]");
    }
}

}  // namespace

at::Tensor exposureOf(const at::Tensor& cleanRadiance) {
    const std::int64_t spp = cleanRadiance.size(1);
    const std::int64_t height = cleanRadiance.size(3), width = cleanRadiance.size(4);
    const at::Tensor rgb =
        (cleanRadiance.narrow(2, 0, 3) + cleanRadiance.narrow(2, 3, 3)).to(at::kDouble).sum(1) / double(spp);
    const at::Tensor luminance = 0.2126 * rgb.select(1, 0) + 0.7152 * rgb.select(1, 1) + 0.0722 * rgb.select(1, 2);
    // The rows the depth scale reads; squares of kExposureBin pixels are kExposureBin / step of them.
    const at::Tensor rows = luminance.slice(1, 0, height, kDepthScaleRowStep);
    const std::int64_t rowsPerSquare = kExposureBin / kDepthScaleRowStep;
    const std::int64_t squaresY = (rows.size(1) + rowsPerSquare - 1) / rowsPerSquare;
    const std::int64_t squaresX = (width + kExposureBin - 1) / kExposureBin;
    const std::vector<std::int64_t> padding{0, squaresX * kExposureBin - width, 0,
                                            squaresY * rowsPerSquare - rows.size(1)};
    auto squareSums = [&](const at::Tensor& values) {  // [B, R, W] -> [B, squares]
        return at::constant_pad_nd(values, padding, 0.0)
            .view({values.size(0), squaresY, rowsPerSquare, squaresX, kExposureBin})
            .sum({2, 4})
            .view({values.size(0), squaresY * squaresX});
    };
    const at::Tensor means = squareSums(rows) / squareSums(at::ones_like(rows.narrow(0, 0, 1)));
    const at::Tensor mean = means.mean(1, true);
    const at::Tensor lit = means > kExposureDarkBin * mean;
    const at::Tensor logMean =
        at::where(lit, at::log(at::where(lit, means, 1.0)), 0.0).sum(1) / lit.sum(1).clamp_min(1).to(at::kDouble);
    const at::Tensor found = (mean.squeeze(1) > 0).logical_and(at::isfinite(mean.squeeze(1)));
    const at::Tensor key = at::exp(logMean);
    const at::Tensor factor = at::where(key < kExposureKeyLow, kExposureKeyLow / key,
                                        at::where(key > kExposureKeyHigh, kExposureKeyHigh / key, 1.0));
    return at::where(found, factor, 0.0);  // exposureForKey (features.h)
}

PreparedInputs prepareInputs(const at::Tensor& samples, const at::Tensor& sequenceExposure) {
    if (samples.dim() != 5 || samples.size(2) != kFeatureCount) {
        throw Error("prepareInputs: samples must be [B, S, 18, H, W]");
    }
    const std::int64_t batch = samples.size(0);
    const std::vector<std::int64_t> perFrame{1, 2, 3, 4};

    // Non-finite and negative radiance reads as 0 everywhere (and is counted).
    const at::Tensor radiance = samples.narrow(2, channel::kDiffuse, 6);
    const at::Tensor finite = at::isfinite(radiance);
    const at::Tensor clean = at::where(finite.logical_and(radiance > 0), radiance, 0.0);
    const at::Tensor invalidCount = finite.logical_not().logical_or(radiance < 0).sum(perFrame);
    const at::Tensor noisy = (clean.narrow(2, 0, 3) + clean.narrow(2, 3, 3)).mean(1);

    // Every other feature: non-finite values read as 0 (the core does the same).
    auto finiteOrZero = [](const at::Tensor& values) { return at::where(at::isfinite(values), values, 0.0); };

    // depthScale = 1 / mean of the positive finite depths of every kDepthScaleRowStep-th row
    // (the core does the same), summed in double so that large frames keep full float precision.
    const at::Tensor depth = finiteOrZero(samples.narrow(2, channel::kDepth, 1));
    const at::Tensor meanRows = depth.slice(3, 0, depth.size(3), kDepthScaleRowStep);
    const at::Tensor hit = at::isfinite(meanRows).logical_and(meanRows > 0);
    const at::Tensor depthSum = at::where(hit, meanRows.to(at::kDouble), 0.0).sum(perFrame);
    const at::Tensor hitCount = hit.sum(perFrame).to(at::kDouble);
    const at::Tensor any = hitCount > 0;
    const at::Tensor scale = at::where(any, hitCount / at::where(any, depthSum, 1.0), 0.0)
                                 .to(samples.scalar_type())
                                 .view({batch, 1, 1, 1, 1});

    // The exposure normalisation: the sequence's, or this frame's where it has none yet (the key
    // is computed only then: every frame of a training window but the first has one).
    at::Tensor exposure;
    if (sequenceExposure.defined()) exposure = sequenceExposure.to(samples.scalar_type());
    if (!exposure.defined() || (exposure <= 0).any().item<bool>()) {
        const at::Tensor own = exposureOf(clean).to(samples.scalar_type());
        exposure = exposure.defined() ? at::where(exposure > 0, exposure, own) : own;
    }
    const at::Tensor factor = at::where(exposure > 0, exposure, 1.0).view({batch, 1, 1, 1, 1});
    // Kept finite as in the core: a huge exposure saturates at log1p(FLT_MAX).
    const at::Tensor exposed = (clean * factor).clamp_max(std::numeric_limits<float>::max());

    at::Tensor networkInput =
        at::cat({at::log1p(exposed), finiteOrZero(samples.narrow(2, channel::kNormal, 3)), depth * scale,
                 finiteOrZero(samples.narrow(2, channel::kAlbedo, kFeatureCount - channel::kAlbedo))},
                2);
    return {networkInput, noisy, invalidCount, exposure};
}

WarpTargets warpTargets(const at::Tensor& motion) {
    checkImage(motion, "motion", 2);
    const std::int64_t height = motion.size(2), width = motion.size(3);
    const at::Tensor clean = at::nan_to_num(motion, 0.0);
    const at::Tensor xs = at::arange(width, clean.options()).view({1, 1, width});
    const at::Tensor ys = at::arange(height, clean.options()).view({1, height, 1});
    return {clean.select(1, 0) + xs, clean.select(1, 1) + ys};
}

at::Tensor warpBilinearUnfused(const at::Tensor& previous, const at::Tensor& motion) {
    checkImage(previous, "the warped buffer", 0);
    const std::int64_t batch = previous.size(0), channels = previous.size(1);
    const std::int64_t height = previous.size(2), width = previous.size(3);
    const WarpTargets target = warpTargets(motion);
    // Clamping the position is the same as clamping both bilinear taps to the border.
    const at::Tensor px = target.x.clamp(0, double(width - 1));
    const at::Tensor py = target.y.clamp(0, double(height - 1));
    const at::Tensor x0f = px.floor().detach(), y0f = py.floor().detach();
    const at::Tensor fx = (px - x0f).unsqueeze(1), fy = (py - y0f).unsqueeze(1);
    const at::Tensor x0 = x0f.to(at::kLong), y0 = y0f.to(at::kLong);
    const at::Tensor x1 = (x0 + 1).clamp_max(width - 1), y1 = (y0 + 1).clamp_max(height - 1);

    const at::Tensor flat = previous.reshape({batch, channels, height * width});
    auto tap = [&](const at::Tensor& y, const at::Tensor& x) {
        const at::Tensor index =
            (y * width + x).view({batch, 1, height * width}).expand({batch, channels, height * width});
        return flat.gather(2, index).view({batch, channels, height, width});
    };
    const at::Tensor top = tap(y0, x0) * (1 - fx) + tap(y0, x1) * fx;
    const at::Tensor bottom = tap(y1, x0) * (1 - fx) + tap(y1, x1) * fx;
    return top * (1 - fy) + bottom * fy;
}

at::Tensor warpCatmullRomUnfused(const at::Tensor& previous, const at::Tensor& motion) {
    checkImage(previous, "the warped buffer", 0);
    const std::int64_t batch = previous.size(0), channels = previous.size(1);
    const std::int64_t height = previous.size(2), width = previous.size(3);
    const WarpTargets target = warpTargets(motion.detach());
    const at::Tensor px = target.x.clamp(0, double(width - 1)), py = target.y.clamp(0, double(height - 1));
    const at::Tensor x0 = px.floor(), y0 = py.floor();
    // Catmull-Rom weights of the taps at -1, 0, 1, 2 around the fraction t, each [B, 1, H, W].
    auto weights = [](const at::Tensor& t) {
        const at::Tensor t2 = t * t, t3 = t2 * t;
        return std::array<at::Tensor, 4>{(-t3 + 2 * t2 - t).mul(0.5).unsqueeze(1),
                                         (3 * t3 - 5 * t2 + 2).mul(0.5).unsqueeze(1),
                                         (-3 * t3 + 4 * t2 + t).mul(0.5).unsqueeze(1), (t3 - t2).mul(0.5).unsqueeze(1)};
    };
    const std::array<at::Tensor, 4> wx = weights(px - x0), wy = weights(py - y0);
    const at::Tensor ix = x0.to(at::kLong), iy = y0.to(at::kLong);

    const at::Tensor flat = previous.reshape({batch, channels, height * width});
    auto tap = [&](int j, int i) {
        const at::Tensor y = (iy + (j - 1)).clamp(0, height - 1), x = (ix + (i - 1)).clamp(0, width - 1);
        const at::Tensor index =
            (y * width + x).view({batch, 1, height * width}).expand({batch, channels, height * width});
        return flat.gather(2, index).view({batch, channels, height, width});
    };
    at::Tensor sum;
    for (int j = 0; j < 4; ++j) {
        at::Tensor row = tap(j, 0) * wx[0];
        for (int i = 1; i < 4; ++i) row = row + tap(j, i) * wx[i];
        sum = j == 0 ? row * wy[0] : sum + row * wy[j];
    }
    // The range of the four nearest taps bounds the result: no ringing, no negative radiance.
    const at::Tensor p00 = tap(1, 1), p01 = tap(1, 2), p10 = tap(2, 1), p11 = tap(2, 2);
    const at::Tensor low = at::minimum(at::minimum(p00, p01), at::minimum(p10, p11));
    const at::Tensor high = at::maximum(at::maximum(p00, p01), at::maximum(p10, p11));
    return at::clamp(sum, low, high);
}

at::Tensor warpBilinear(const at::Tensor& previous, const at::Tensor& motion) {
    if (fusedWarpApplies(previous, motion)) return fusedWarpBilinear(previous, motion);
    return warpBilinearUnfused(previous, motion);
}

at::Tensor warpCatmullRom(const at::Tensor& previous, const at::Tensor& motion) {
    if (fusedWarpApplies(previous, motion.detach())) return fusedWarpCatmullRom(previous, motion.detach());
    return warpCatmullRomUnfused(previous, motion);
}

at::Tensor maxPool2x2(const at::Tensor& input) { return at::max_pool2d(input, {2, 2}, {2, 2}, {0, 0}, {1, 1}, true); }

at::Tensor upsampleNearest(const at::Tensor& input, std::int64_t height, std::int64_t width) {
    const at::TensorOptions index = input.options().dtype(at::kLong);
    const at::Tensor rows = at::div(at::arange(height, index), 2, "floor");
    const at::Tensor cols = at::div(at::arange(width, index), 2, "floor");
    return input.index_select(2, rows).index_select(3, cols);
}

at::Tensor affinityFilterUnfused(const at::Tensor& radiance, const KernelParams& kernel, int tapSize, int dilation,
                                 const TemporalTaps* temporal) {
    checkImage(radiance, "the filtered signal", 0);
    WeightedSum sum = spatialSum(radiance, kernel, tapSize, dilation);
    if (temporal) {
        checkImage(temporal->output, "the warped output", radiance.size(1));
        const std::int64_t height = radiance.size(2), width = radiance.size(3);
        const std::vector<std::int64_t> padding{1, 1, 1, 1};
        const at::Tensor paddedOutput = at::constant_pad_nd(temporal->output, padding, 0);
        const at::Tensor paddedFeatures = at::constant_pad_nd(temporal->features, padding, 0);
        const at::Tensor paddedValid = at::constant_pad_nd(temporal->valid, padding, 0);  // outside = invalid
        const at::Tensor negativeB2 = -(temporal->bandwidth * temporal->bandwidth);
        for (std::int64_t dy = -1; dy <= 1; ++dy) {
            for (std::int64_t dx = -1; dx <= 1; ++dx) {
                const at::Tensor neighbour = shifted(paddedFeatures, 1, dy, dx, height, width);
                const at::Tensor weight = shifted(paddedValid, 1, dy, dx, height, width) *
                                          at::exp(negativeB2 * squaredDistance(kernel.features, neighbour));
                sum.numerator = sum.numerator + weight * shifted(paddedOutput, 1, dy, dx, height, width);
                sum.denominator = sum.denominator + weight;
            }
        }
    }
    return sum.numerator / (sum.denominator + kAffinityEpsilon);
}

at::Tensor affinityFilter(const at::Tensor& radiance, const KernelParams& kernel, int tapSize, int dilation) {
    checkImage(radiance, "the filtered signal", 0);
    if (fusedAffinityFilterApplies(radiance)) return fusedAffinityFilter(radiance, kernel, tapSize, dilation, nullptr);
    return affinityFilterUnfused(radiance, kernel, tapSize, dilation, nullptr);
}

at::Tensor affinityFilterTemporal(const at::Tensor& radiance, const KernelParams& kernel, int tapSize, int dilation,
                                  const TemporalTaps& temporal) {
    checkImage(radiance, "the filtered signal", 0);
    checkImage(temporal.output, "the warped output", radiance.size(1));
    if (fusedAffinityFilterApplies(radiance))
        return fusedAffinityFilter(radiance, kernel, tapSize, dilation, &temporal);
    return affinityFilterUnfused(radiance, kernel, tapSize, dilation, &temporal);
}

}  // namespace affinity::train
