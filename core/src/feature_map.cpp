#include "feature_map.h"

#include <algorithm>

namespace affinity {

void FeatureMap::resize(int height, int width, int channels) {
    height_ = height;
    width_ = width;
    channels_ = channels;
    if (size() > capacity_) {
        data_.reset(static_cast<float*>(::operator new[](size() * sizeof(float), std::align_val_t(64))));
        capacity_ = size();
    }
}

void FeatureMap::fill(float value) { std::fill(data_.get(), data_.get() + size(), value); }

}  // namespace affinity
