#pragma once
// The extension's pre-roll in training (docs/TRAINING.md, "Pre-roll"). Before the first frame of
// a render the Blender extension renders that frame again with other seeds and denoises those
// renders as frames of a still camera, their output unused, so the first frame the user sees
// already has a history (docs/BLENDER.md, "Pre-roll"). A training clip that starts cold teaches
// the network a first frame it never meets in the extension; a pre-rolled clip gets the same
// history from the first frame's spare samples (those the step's spp leaves unused), which are
// independent of its own as the extension's other seeds are.
#include <vector>

#include <ATen/core/Tensor.h>

#include "train_augment.h"

namespace affinity::train {

// How many pre-roll frames a clip drawn at `spp` of `heldSpp` samples per pixel can have: groups
// of `spp` samples disjoint from the frame's own and from each other, at most `wanted`.
int prerollFrameCount(int spp, int heldSpp, int wanted);

// `clip` with one frame per group before its own. groups[g]: [S, 18, h, w], the clip's first frame
// rendered again (S of its spare samples). Each pre-roll frame has the first frame's reference
// and zero motion; its history is invalid for the first (it starts the history) and valid after,
// as the extension gives them. The clip's own first frame gets zero motion and valid history:
// the frame before it is the same frame, from the same camera.
Clip withPreroll(const Clip& clip, const std::vector<at::Tensor>& groups);

}  // namespace affinity::train
