#include "train_loss.h"

#include <ATen/ATen.h>

#include "affinity/error.h"

namespace affinity::train {

at::Tensor smapeLoss(const at::Tensor& image, const at::Tensor& reference) {
    return ((image - reference).abs() / (image.abs() + reference.abs() + kSmapeEpsilon)).mean();
}

LossTerms sequenceLoss(const std::vector<at::Tensor>& outputs, const std::vector<at::Tensor>& references,
                       const std::vector<std::vector<at::Tensor>>& bandwidths) {
    if (outputs.empty() || outputs.size() != references.size()) {
        throw Error("sequenceLoss: need as many references as outputs (and at least one)");
    }
    if (!bandwidths.empty() && bandwidths.size() != outputs.size()) {
        throw Error("sequenceLoss: bandwidths must be empty or one entry per frame");
    }
    const std::size_t frames = outputs.size();
    const at::TensorOptions options = outputs[0].options();
    at::Tensor spatial = at::zeros({}, options), temporal = at::zeros({}, options);
    at::Tensor regulariser = at::zeros({}, options);
    for (std::size_t t = 0; t < frames; ++t) {
        spatial = spatial + smapeLoss(outputs[t], references[t]);
        if (t > 0) {
            temporal = temporal + smapeLoss(outputs[t] - outputs[t - 1], references[t] - references[t - 1]);
        }
        if (!bandwidths.empty()) {
            for (const at::Tensor& bandwidth : bandwidths[t]) regulariser = regulariser + bandwidth.square().mean();
        }
    }
    LossTerms terms;
    terms.spatial = spatial / double(frames);
    terms.temporal = frames > 1 ? temporal / double(frames - 1) : temporal;
    terms.regulariser = regulariser / double(frames);
    terms.total = terms.spatial + kTemporalWeight * terms.temporal + kRegulariserWeight * terms.regulariser;
    return terms;
}

}  // namespace affinity::train
