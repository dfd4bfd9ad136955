#pragma once
// Changes to a trained model's weights that keep the function it computes, so that a larger model
// can be fine-tuned from a trained one instead of trained from scratch: how the shipped medium
// model was made (docs/TRAINING.md).
#include <vector>

#include "affinity/weights.h"
#include "train/weights_writer.h"

namespace affinity::train {

// The trained model grown to the wider layers of `fresh` (a newly initialised model of the same
// depths, embedding, kernels and options, every U-Net width at least the trained one's), computing
// the same function (Net2Net-style): the trained weights sit in the first channels of every
// layer, the new channels keep their fresh weights coming in, and every weight from a new channel
// into an old one is 0. Training can then use the new channels from where the trained model
// stands. Throws affinity::Error naming what differs when the two do not fit.
std::vector<NamedTensor> widened(const Weights& trained, const Weights& fresh);

}  // namespace affinity::train
