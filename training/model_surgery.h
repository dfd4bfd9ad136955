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

// The trained model with one more dilated kernel: K + 1 kernels, the new one last (dilation 2^K,
// so the footprint doubles) and the one with the temporal taps. Not the same function: the
// history then joins after the wide pass instead of the old last one. The head's new outputs
// start as copies of the old last kernel's (features, bandwidth, centre weight), the bandwidth
// multiplied by `bandwidthScale` (> 1: the wide pass starts as a stricter, more edge-keeping
// filter). The temporal taps compare the new last kernel's features, which start equal to the
// old ones, so the history's weights start where they were. Throws affinity::Error for a scale
// that is not positive or a model that already has the most kernels a file may hold.
std::vector<NamedTensor> withKernelAdded(const Weights& trained, double bandwidthScale);

// The same weights with config.light_restoration set to `on` (docs/MODEL.md sections 8 and 10):
// the switch is a property of the file, not a change of the network.
std::vector<NamedTensor> withLightRestoration(const Weights& trained, bool on);

// The same weights with config.temporal_gain_percent set to `percent` (docs/MODEL.md sections 7-8;
// 100: the tensor left out, as in files written before it existed). Throws affinity::Error for a
// percent outside 1..kMaxTemporalGainPercent.
std::vector<NamedTensor> withTemporalGain(const Weights& trained, int percent);

}  // namespace affinity::train
