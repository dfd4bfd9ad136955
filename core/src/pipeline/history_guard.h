#pragma once
// Bright-history guard (docs/MODEL.md section 10, "Bright-history guard"). The temporal kernel
// weighs the previous output at the taps whose features it finds alike the pixel's. A model can
// learn to find the previous output of a lamp alike the dark pixel beside it: a pre-rolled first
// frame, or any frame after one where the lamp's light reached further, then spreads the lamp into
// that pixel, a halo the peak guard cannot see (the halo is a line whose pixels vouch for each
// other). So a temporal tap gives no weight where its previous output's luminance exceeds
// kHistoryGuardRatio x (the pixel's luminance in this frame before the last kernel, plus a floor of
// kHistoryGuardFloorShare x the frame's mean input luminance): history far brighter than anything
// this frame shows there is a stale light, not the pixel's. The floor keeps dark pixels, whose own
// estimate is near zero, taking the ordinary history of a dim region.
#include "kernels/feature_map.h"

namespace affinity {

inline constexpr float kHistoryGuardRatio = 8.0f;
inline constexpr float kHistoryGuardFloorShare = 0.2f;

// The floor for a frame whose noisy radiance is `signal` (height x width x 3): kHistoryGuardFloorShare
// x its mean luminance.
float historyGuardFloor(const FeatureMap& signal);

}  // namespace affinity
