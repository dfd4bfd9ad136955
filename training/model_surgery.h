#pragma once
// Changes to a trained model's weights that keep the function it computes, so that a new model
// option can be fine-tuned from a trained model instead of trained from scratch.
#include <vector>

#include "affinity/weights.h"
#include "train/weights_writer.h"

namespace affinity::train {

// The tensors of a model with emission bypass, plus the emission lambda of docs/MODEL.md
// section 3: one more head output whose weights and bias copy lambda's, so the result computes
// the same as the input until training moves the two apart. Throws affinity::Error naming the
// source when the model has no emission bypass or already has an emission lambda.
std::vector<NamedTensor> withEmissionLambda(const Weights& weights);

}  // namespace affinity::train
