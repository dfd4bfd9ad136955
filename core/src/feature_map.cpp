#include "feature_map.h"

#include <algorithm>

namespace affinity {

void FeatureMap::resize(int height, int width, int channels) {
    height_ = height;
    width_ = width;
    channels_ = channels;
    if (size() > capacity_) {
        data_.reset();  // first: the old and the new buffer are never held together
        capacity_ = 0;
        data_.reset(static_cast<float*>(::operator new[](size() * sizeof(float), std::align_val_t(64))));
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

void FeatureMap::fill(float value) { std::fill(data_.get(), data_.get() + size(), value); }

}  // namespace affinity
