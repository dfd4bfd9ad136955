#pragma once
// Sharp warping of the previous frame's radiance into the current frame by its motion vectors
// (docs/MODEL.md section 3). A bilinear lookup is a low-pass filter at every fractional
// position, and a history that is resampled every frame and blended back into itself
// blurs a little more each frame: fine texture fades under a moving camera. Catmull-Rom
// weights (4x4 taps) keep the detail; the result is clamped to the range of the four nearest
// taps, channel by channel, so the cubic's overshoot can neither ring at edges nor make
// radiance negative.
#include "kernels/feature_map.h"

namespace affinity {

// output(p) = clamped Catmull-Rom lookup of `previous` at (x + motion.x, y + motion.y), the
// position clamped to the image and the taps to its border. motion: height x width x 2 floats.
void warpCatmullRom(const FeatureMap& previous, const float* motion, FeatureMap& output);

// Rows [begin, end) of the above into `output`, a ring of the previous map's width and channels
// holding image row y at row y % height() (or a whole image).
void warpCatmullRomRows(const FeatureMap& previous, const float* motion, int begin, int end, FeatureMap& output);

}  // namespace affinity
