#include "train_loss.h"

#include <algorithm>

#include <ATen/ATen.h>

#include "affinity/error.h"

namespace affinity::train {

at::Tensor smapeLoss(const at::Tensor& image, const at::Tensor& reference) {
    return ((image - reference).abs() / (image.abs() + reference.abs() + kSmapeEpsilon)).mean();
}

namespace {

// mean |dt O - dt O*| / (mean |O*| + 0.01), the means taken per crop of the batch.
at::Tensor absoluteTemporalLoss(const at::Tensor& change, const at::Tensor& referenceChange,
                                const at::Tensor& reference) {
    const std::vector<std::int64_t> perCrop{1, 2, 3};
    const at::Tensor brightness = reference.abs().mean(perCrop) + kSmapeEpsilon;
    return ((change - referenceChange).abs().mean(perCrop) / brightness).mean();
}

}  // namespace

LossTerms sequenceLoss(const std::vector<at::Tensor>& outputs, const std::vector<at::Tensor>& references,
                       const std::vector<std::vector<at::Tensor>>& bandwidths, const LossWeights& weights) {
    if (outputs.empty() || outputs.size() != references.size()) {
        throw Error("sequenceLoss: need as many references as outputs (and at least one)");
    }
    if (!bandwidths.empty() && bandwidths.size() != outputs.size()) {
        throw Error("sequenceLoss: bandwidths must be empty or one entry per frame");
    }
    const std::size_t frames = outputs.size();
    const at::TensorOptions options = outputs[0].options();
    at::Tensor spatial = at::zeros({}, options), temporal = at::zeros({}, options);
    at::Tensor absoluteTemporal = at::zeros({}, options);
    at::Tensor regulariser = at::zeros({}, options);
    for (std::size_t t = 0; t < frames; ++t) {
        spatial = spatial + smapeLoss(outputs[t], references[t]);
        if (t > 0) {
            const at::Tensor change = outputs[t] - outputs[t - 1];
            const at::Tensor referenceChange = references[t] - references[t - 1];
            temporal = temporal + smapeLoss(change, referenceChange);
            if (weights.absoluteTemporal != 0) {
                absoluteTemporal = absoluteTemporal + absoluteTemporalLoss(change, referenceChange, references[t]);
            }
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
    terms.regulariser = regulariser / double(frames);
    terms.total = terms.spatial + weights.temporal * terms.temporal +
                  weights.absoluteTemporal * terms.absoluteTemporal + kRegulariserWeight * terms.regulariser;
    return terms;
}

}  // namespace affinity::train
