#include "kernels/feature_map.h"

#include <algorithm>

#include "kernels/map_memory.h"

namespace affinity {

FeatureMap::~FeatureMap() { releaseMapMemory(data_, capacity_); }

void FeatureMap::resize(int height, int width, int channels) {
    height_ = height;
    width_ = width;
    channels_ = channels;
    if (size() > capacity_) {
        releaseMapMemory(data_, capacity_);  // first: the old and the new buffer are never held together
        data_ = nullptr;
        capacity_ = 0;
        data_ = allocateMapMemory(size());
        capacity_ = size();
    }
}

FeatureMap& FeatureMap::operator=(const FeatureMap& other) {
    if (this != &other) {
        resize(other.height_, other.width_, other.channels_);
        std::copy(other.data(), other.data() + other.size(), data());
    }
    return *this;
}

void FeatureMap::fill(float value) { std::fill(data_, data_ + size(), value); }

}  // namespace affinity
