#include "pipeline/feature_map_pool.h"

#include <utility>

namespace affinity {

FeatureMap FeatureMapPool::take(int height, int width, int channels) {
    const std::size_t needed = std::size_t(height) * std::size_t(width) * std::size_t(channels);
    std::size_t best = free_.size(), largest = free_.size();
    for (std::size_t i = 0; i < free_.size(); ++i) {
        const std::size_t capacity = free_[i].capacity();
        if (capacity >= needed && (best == free_.size() || capacity < free_[best].capacity())) best = i;
        if (largest == free_.size() || capacity > free_[largest].capacity()) largest = i;
    }
    std::size_t pick = best != free_.size() ? best : largest;
    // A free map much larger than the request is kept for a later, larger request: cutting it
    // down now would cost a new allocation then. kKeepRatio is where peak memory was lowest at
    // 1080p and 720p, streamed and whole frames, over the models (bench_denoiser; the figures
    // are in commit 2b213e4's message).
    if (best != free_.size() && free_[best].capacity() > keepRatio_ * needed) pick = free_.size();
    FeatureMap map;
    if (pick != free_.size()) {
        map = std::move(free_[pick]);
        free_.erase(free_.begin() + std::ptrdiff_t(pick));
    }
    const std::size_t before = map.capacity();
    map.resize(height, width, channels);
    heldCapacity_ += map.capacity() - before;
    return map;
}

void FeatureMapPool::give(FeatureMap& map) {
    if (map.capacity() == 0) return;
    free_.push_back(std::move(map));
    map = FeatureMap();
}

std::size_t FeatureMapPool::freeCapacity() const {
    std::size_t total = 0;
    for (const FeatureMap& map : free_) total += map.capacity();
    return total;
}

}  // namespace affinity
