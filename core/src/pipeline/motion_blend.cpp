#include "pipeline/motion_blend.h"

#include <cstddef>

#include "kernels/bilinear_warp.h"

namespace affinity {

void blendAlongMotion(const FeatureMap& previous, const float* motion, const float* valid, float weight,
                      FeatureMap& current, FeatureMapPool& pool, bool squared) {
    FeatureMap warped = pool.take(current.height(), current.width(), 1);
    warpBilinear(previous, motion, warped);
    const float rest = 1.0f - weight;
    const float old = squared ? weight * weight : weight, fresh = squared ? rest * rest : rest;
    const std::size_t pixels = std::size_t(current.height()) * std::size_t(current.width());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(pixels); ++p) {
        if (valid[p] > 0.5f) current.data()[p] = old * warped.data()[p] + fresh * current.data()[p];
    }
    pool.give(warped);
}

}  // namespace affinity
