#pragma once
// Buffers lent out and handed back within a frame, so that stages whose lifetimes do not overlap
// share memory, and the same pages serve every frame (touching fresh pages costs about as much
// as a convolution layer at 1080p). Peak memory is the largest set of maps alive at once.
#include <vector>

#include "kernels/feature_map.h"

namespace affinity {

class FeatureMapPool {
public:
    // A map of the given size with undefined contents: the free map that fits most tightly
    // unless it is more than keepRatio() times the size needed (then a new one), else the
    // largest free map grown, else a new one.
    static constexpr std::size_t kKeepRatio = 6;
    FeatureMap take(int height, int width, int channels);
    std::size_t keepRatio() const { return keepRatio_; }
    void setKeepRatio(std::size_t ratio) { keepRatio_ = ratio; }
    // Takes `map` back (leaving it empty) for later take() calls.
    void give(FeatureMap& map);

    // Floats held by free maps (for tests).
    std::size_t freeCapacity() const;
    // Floats of every map the pool has made, lent or free (maps dropped elsewhere still count).
    std::size_t heldCapacity() const { return heldCapacity_; }

private:
    std::vector<FeatureMap> free_;
    std::size_t keepRatio_ = kKeepRatio;
    std::size_t heldCapacity_ = 0;
};

}  // namespace affinity
