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

// The trained model grown to the wider layers of `fresh` (a newly initialised model of the same
// depths, embedding, kernels and options, every U-Net width at least the trained one's), computing
// the same function (Net2Net-style): the trained weights sit in the first channels of every
// layer, the new channels keep their fresh weights coming in, and every weight from a new channel
// into an old one is 0. Training can then use the new channels from where the trained model
// stands. Throws affinity::Error naming what differs when the two do not fit.
std::vector<NamedTensor> widened(const Weights& trained, const Weights& fresh);

// The trained model with only `channels` of its E embedding channels: those the U-Net's first
// convolution weighs most (L2 norm of its weights on the channel, current and history parts
// together), in their original order. Not the same function (unless the dropped channels had no
// weight), a start for fine-tuning a cheaper model: the embedding is what the denoiser keeps at
// full resolution twice (current and history), so E sets much of its memory and the U-Net's
// first convolution's cost. Throws affinity::Error unless 1 <= channels <= E.
std::vector<NamedTensor> withNarrowerEmbedding(const Weights& trained, int channels);

// The trained model with every convolution of U-Net level `level` (its encoder and decoder
// stacks) cut to `channels` outputs: per convolution those with the largest product of the
// incoming weights' and the reading layers' outgoing weights' L2 norms, in their original order;
// the layers that read them lose the other inputs. Not the same function (unless the dropped
// channels were never read), a start for fine-tuning a cheaper model: level 0 runs at full
// resolution and carries most of the U-Net's FLOPs. Throws affinity::Error unless the level
// exists and 1 <= channels <= each of its widths.
std::vector<NamedTensor> withNarrowerLevel(const Weights& trained, int level, int channels);

}  // namespace affinity::train
