#pragma once
// Moving a model's parameters to and from weights files (docs/MODEL.md sections 8-9). Names
// are named_parameters() keys; the configuration travels as the config.* int32 tensors.
#include <string>
#include <vector>

#include "affinity/weights.h"
#include "affinity_model.h"
#include "train/weights_writer.h"

namespace affinity::train {

// Every parameter (as float32) followed by config.version, kernels, affinity_features, kernel_size.
std::vector<NamedTensor> modelTensors(const AffinityModel& model);
// modelTensors written with writeWeightsFile (atomic); throws affinity::Error on failure.
void exportWeights(const AffinityModel& model, const std::string& path);

// A float32 model with the structure and values of a weights file (configFromWeights checks
// every tensor's name and shape first).
AffinityModel modelFromWeights(const Weights& weights);

}  // namespace affinity::train
