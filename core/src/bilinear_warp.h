#pragma once
// Bilinear warping of a previous frame's maps into the current frame by its motion vectors
// (docs/MODEL.md section 3): the temporal history, the previous output and features.
#include "feature_map.h"

namespace affinity {

// output(p) = bilinear lookup of `previous` at (x + motion.x, y + motion.y), border-clamped.
// motion: height x width x 2 floats (frame layout).
void warpBilinear(const FeatureMap& previous, const float* motion, FeatureMap& output);

// Rows [begin, end) of the above into `output`, a ring of the previous map's width and channels
// holding image row y at row y % height() (or a whole image).
void warpBilinearRows(const FeatureMap& previous, const float* motion, int begin, int end, FeatureMap& output);

// Two maps of the same size warped by the same motion in one pass: each pixel's taps and weights
// are found once for both, and a few-channel map rides along with a wider one instead of paying
// the per-pixel work alone. The same values as two single warps, bit for bit.
void warpBilinear(const FeatureMap& first, const FeatureMap& second, const float* motion, FeatureMap& firstOutput,
                  FeatureMap& secondOutput);
void warpBilinearRows(const FeatureMap& first, const FeatureMap& second, const float* motion, int begin, int end,
                      FeatureMap& firstOutput, FeatureMap& secondOutput);

}  // namespace affinity
