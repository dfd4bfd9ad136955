#include "model_surgery.h"

#include "affinity/error.h"
#include "model_config.h"

namespace affinity::train {

namespace {

NamedTensor copyOf(const TensorView& view) {
    NamedTensor tensor{view.name, view.dtype, view.shape, {}, {}};
    if (view.dtype == DType::Int32) {
        const auto* values = static_cast<const std::int32_t*>(view.data);
        tensor.ints.assign(values, values + view.count);
    } else {
        const auto* values = static_cast<const float*>(view.data);
        tensor.floats.assign(values, values + view.count);
    }
    return tensor;
}

// Appends a copy of the last output channel of a [P, ...] tensor (lambda is the head's last).
void repeatLastOutput(NamedTensor& tensor) {
    const std::size_t perOutput = tensor.floats.size() / std::size_t(tensor.shape[0]);
    const std::vector<float> last(tensor.floats.end() - std::ptrdiff_t(perOutput), tensor.floats.end());
    tensor.floats.insert(tensor.floats.end(), last.begin(), last.end());
    tensor.shape[0] += 1;
}

}  // namespace

std::vector<NamedTensor> withEmissionLambda(const Weights& weights) {
    const ModelConfig config = configFromWeights(weights);  // also checks the head's shape
    if (!config.emissionBypass)
        throw Error(weights.source() + ": an emission lambda needs a model with emission bypass");
    if (config.emissionLambda) throw Error(weights.source() + ": the model already has an emission lambda");
    std::vector<NamedTensor> tensors;
    for (const std::string& name : weights.names()) {
        tensors.push_back(copyOf(weights.tensor(name)));
        if (name == "unet.head.weight" || name == "unet.head.bias") repeatLastOutput(tensors.back());
    }
    tensors.push_back({"config.emission_lambda", DType::Int32, {1}, {}, {1}});
    return tensors;
}

}  // namespace affinity::train
