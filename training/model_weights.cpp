#include "model_weights.h"

#include <torch/nn/module.h>
#include <torch/utils.h>

#include "affinity/error.h"

namespace affinity::train {

std::vector<NamedTensor> modelTensors(const AffinityModel& model) {
    std::vector<NamedTensor> tensors;
    for (const auto& item : model->named_parameters()) {
        const torch::Tensor values = item.value().detach().to(torch::kCPU, torch::kFloat).contiguous();
        NamedTensor tensor;
        tensor.name = item.key();
        tensor.dtype = DType::Float32;
        tensor.shape.assign(values.sizes().begin(), values.sizes().end());
        tensor.floats.assign(values.data_ptr<float>(), values.data_ptr<float>() + values.numel());
        tensors.push_back(std::move(tensor));
    }
    const ModelConfig& config = model->config();
    auto integer = [&](const std::string& name, int value) {
        tensors.push_back({name, DType::Int32, {1}, {}, {value}});
    };
    integer("config.version", 1);
    integer("config.kernels", config.kernels);
    integer("config.affinity_features", config.affinityFeatures);
    integer("config.kernel_size", config.kernelSize);
    if (config.lightRestoration) integer("config.light_restoration", 1);
    if (config.temporalGainPercent != 100) integer("config.temporal_gain_percent", config.temporalGainPercent);
    return tensors;
}

void exportWeights(const AffinityModel& model, const std::string& path) { writeWeightsFile(path, modelTensors(model)); }

AffinityModel modelFromWeights(const Weights& weights) {
    AffinityModel model(configFromWeights(weights));
    torch::NoGradGuard noGrad;
    for (auto& item : model->named_parameters()) {
        torch::Tensor& parameter = item.value();
        const std::vector<std::int64_t> shape(parameter.sizes().begin(), parameter.sizes().end());
        const float* values = weights.floats(item.key(), shape);
        parameter.copy_(torch::from_blob(const_cast<float*>(values), shape, torch::kFloat));
    }
    return model;
}

}  // namespace affinity::train
