#pragma once
// Image error metrics on linear RGB buffers of equal size (n floats). Definitions follow
// ALGORITHM.md section 10.
#include <cstddef>

namespace affinity {

// mean |a - b| / (|a| + |b| + 0.01) over pixels and channels.
double smape(const float* image, const float* reference, std::size_t n);
// 0.5 * mean (a - b)^2 / (b^2 + 0.01).
double relativeMse(const float* image, const float* reference, std::size_t n);
// PSNR in dB after tone mapping both with x / (1 + x) (values in [0, 1)).
double tonemappedPsnr(const float* image, const float* reference, std::size_t n);

}  // namespace affinity
