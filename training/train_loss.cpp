#include "train_loss.h"

#include <algorithm>
#include <cmath>

#include <ATen/ATen.h>

#include "affinity/error.h"
#include "affinity_ops.h"

namespace affinity::train {

at::Tensor smapeLoss(const at::Tensor& image, const at::Tensor& reference) {
    return ((image - reference).abs() / (image.abs() + reference.abs() + kSmapeEpsilon)).mean();
}

at::Tensor displayedImage(const at::Tensor& image) {
    const at::Tensor positive = image.clamp_min(0.0);
    const double gamma = 1.0 / 2.2;
    return (positive / (positive + 1.0) + kDisplayedEpsilon).pow(gamma) - std::pow(kDisplayedEpsilon, gamma);
}

at::Tensor cellMeans(const at::Tensor& image, int cell) {
    if (cell < 1) throw Error("cellMeans: the cell size must be at least 1");
    const std::int64_t padBottom = (cell - image.size(2) % cell) % cell,
                       padRight = (cell - image.size(3) % cell) % cell;
    const std::vector<std::int64_t> padding{0, padRight, 0, padBottom};
    const at::Tensor sums = at::avg_pool2d(at::constant_pad_nd(image, padding, 0.0), cell);
    const at::Tensor counts =
        at::avg_pool2d(at::constant_pad_nd(at::ones_like(image.narrow(1, 0, 1)), padding, 0.0), cell);
    return sums / counts;
}

namespace {

// The temporal terms of one frame pair. mask [B, 1, H, W] (1: the pixel counts) or undefined
// (every pixel counts); the means run over counted pixels and the channels.
struct TemporalPair {
    at::Tensor change, referenceChange, mask;

    at::Tensor maskedMean(const at::Tensor& values, at::IntArrayRef dims) const {
        if (!mask.defined()) return values.mean(dims);
        const at::Tensor counted = (mask * at::ones_like(values)).sum(dims).clamp_min(1.0);
        return (values * mask).sum(dims) / counted;
    }
    at::Tensor smape() const {
        const at::Tensor error =
            (change - referenceChange).abs() / (change.abs() + referenceChange.abs() + kSmapeEpsilon);
        return maskedMean(error, {0, 1, 2, 3});
    }
    // mean |dt O - dt O*| / (mean |O*| + 0.01), the means taken per crop of the batch
    // (loss_weights.h).
    at::Tensor absolute(const at::Tensor& reference) const {
        const std::vector<std::int64_t> perCrop{1, 2, 3};
        const at::Tensor brightness = reference.abs().mean(perCrop, /*keepdim=*/true) + kSmapeEpsilon;
        const at::Tensor difference = (change - referenceChange).abs();
        return (maskedMean(difference, perCrop) / brightness.flatten()).mean();
    }
};

// 1 where frame t's history is valid and its warp target lies inside the crop (as the
// benchmark's temporal error counts pixels).
at::Tensor countedPixels(const FrameMotion& frame) {
    const std::int64_t height = frame.motion.size(2), width = frame.motion.size(3);
    const auto [px, py] = warpTargets(frame.motion);
    const at::Tensor inside = (px >= 0) & (px <= double(width - 1)) & (py >= 0) & (py <= double(height - 1));
    return ((frame.valid.select(1, 0) > 0.5) & inside).unsqueeze(1).to(frame.motion.scalar_type());
}

}  // namespace

LossTerms sequenceLoss(const std::vector<at::Tensor>& outputs, const std::vector<at::Tensor>& references,
                       const std::vector<std::vector<at::Tensor>>& bandwidths, const LossWeights& weights,
                       const std::vector<FrameMotion>& motions) {
    if (outputs.empty() || outputs.size() != references.size()) {
        throw Error("sequenceLoss: need as many references as outputs (and at least one)");
    }
    if (!bandwidths.empty() && bandwidths.size() != outputs.size()) {
        throw Error("sequenceLoss: bandwidths must be empty or one entry per frame");
    }
    if (weights.warpedTemporal && motions.size() != outputs.size()) {
        throw Error("sequenceLoss: the warped temporal terms need one motion per frame");
    }
    const std::size_t frames = outputs.size();
    const at::TensorOptions options = outputs[0].options();
    at::Tensor spatial = at::zeros({}, options), temporal = at::zeros({}, options);
    at::Tensor absoluteTemporal = at::zeros({}, options), coarse = at::zeros({}, options);
    at::Tensor regulariser = at::zeros({}, options), displayed = at::zeros({}, options);
    // The image terms weighted (the first frame by weights.firstFrame), for the total.
    at::Tensor weightedSpatial = at::zeros({}, options), weightedCoarse = at::zeros({}, options);
    at::Tensor weightedDisplayed = at::zeros({}, options);
    for (std::size_t t = 0; t < frames; ++t) {
        const double frameWeight = t == 0 ? weights.firstFrame : 1.0;
        const at::Tensor frameSpatial = smapeLoss(outputs[t], references[t]);
        spatial = spatial + frameSpatial;
        weightedSpatial = weightedSpatial + frameWeight * frameSpatial;
        if (weights.coarse != 0) {
            const at::Tensor frameCoarse =
                smapeLoss(cellMeans(outputs[t], weights.coarseCell), cellMeans(references[t], weights.coarseCell));
            coarse = coarse + frameCoarse;
            weightedCoarse = weightedCoarse + frameWeight * frameCoarse;
        }
        if (weights.displayed != 0) {
            const at::Tensor frameDisplayed = (displayedImage(outputs[t]) - displayedImage(references[t])).abs().mean();
            displayed = displayed + frameDisplayed;
            weightedDisplayed = weightedDisplayed + frameWeight * frameDisplayed;
        }
        if (t > 0) {
            TemporalPair pair;
            if (weights.warpedTemporal) {
                const at::Tensor& motion = motions[t].motion;
                pair = {outputs[t] - warpBilinear(outputs[t - 1], motion),
                        references[t] - warpBilinear(references[t - 1], motion), countedPixels(motions[t])};
            } else {
                pair = {outputs[t] - outputs[t - 1], references[t] - references[t - 1], at::Tensor()};
            }
            temporal = temporal + pair.smape();
            if (weights.absoluteTemporal != 0) absoluteTemporal = absoluteTemporal + pair.absolute(references[t]);
        }
        if (!bandwidths.empty()) {
            for (const at::Tensor& bandwidth : bandwidths[t]) regulariser = regulariser + bandwidth.square().mean();
        }
    }
    LossTerms terms;
    terms.spatial = spatial / double(frames);
    const double pairs = double(std::max<std::size_t>(frames - 1, 1));
    terms.temporal = temporal / pairs;
    terms.absoluteTemporal = absoluteTemporal / pairs;
    terms.coarse = coarse / double(frames);
    terms.regulariser = regulariser / double(frames);
    terms.displayed = displayed / double(frames);
    const double frameWeights = weights.firstFrame + double(frames - 1);
    terms.total = weightedSpatial / frameWeights + weights.temporal * terms.temporal +
                  weights.absoluteTemporal * terms.absoluteTemporal + weights.coarse * weightedCoarse / frameWeights +
                  weights.displayed * weightedDisplayed / frameWeights + kRegulariserWeight * terms.regulariser;
    return terms;
}

}  // namespace affinity::train
