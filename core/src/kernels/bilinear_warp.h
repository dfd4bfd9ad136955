#pragma once
// Bilinear warping of a previous frame's maps into the current frame by its motion vectors
// (docs/MODEL.md section 3): the embedding history and the temporal kernel's features (the
// radiance is warped sharper: catmull_rom_warp.h).
#include "kernels/feature_map.h"

namespace affinity {

// output(p) = bilinear lookup of `previous` at (x + motion.x, y + motion.y), border-clamped;
// NaN motion reads as 0. motion: height x width x 2 floats (frame layout).
void warpBilinear(const FeatureMap& previous, const float* motion, FeatureMap& output);

// Rows [begin, end) of the above into `output`, a ring of the previous map's width and channels
// holding image row y at row y % height() (or a whole image).
void warpBilinearRows(const FeatureMap& previous, const float* motion, int begin, int end, FeatureMap& output);

// Throws unless rows [begin, end) are inside `previous`, `output` (not `previous` itself) holds
// them, and both have the same width and channels: the argument check of every warp.
void checkWarpRows(const char* warp, const FeatureMap& previous, int begin, int end, const FeatureMap& output);

}  // namespace affinity
