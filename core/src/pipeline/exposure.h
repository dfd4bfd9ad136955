#pragma once
// The exposure normalisation of docs/MODEL.md section 1: how much a sequence's radiance is scaled
// before the embedding takes its log, so that a scene lit far brighter or dimmer than the training
// scenes is denoised as the brightest or dimmest of those (the filters themselves are linear in
// the radiance and see it unscaled).
#include "network/embedding.h"

namespace affinity {

// exposureForKey(key of the frame's radiance) (features.h), or 0 when the frame is black (no
// square brighter than 0). Non-finite or negative radiance reads as 0, as in the embedding.
// Multithreaded; the result does not depend on the thread count.
float exposureOf(const SampleBands& frame, int height);

}  // namespace affinity
