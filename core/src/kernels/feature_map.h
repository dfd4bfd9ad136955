#pragma once
// An image of C float channels per pixel, stored NHWC (channels of a pixel contiguous, rows
// top to bottom) in 64-byte aligned memory: the buffer type of every denoiser stage.
#include <cstddef>
#include <utility>

namespace affinity {

class FeatureMap {
public:
    FeatureMap() = default;
    FeatureMap(int height, int width, int channels) { resize(height, width, channels); }
    FeatureMap(const FeatureMap& other) { *this = other; }
    FeatureMap& operator=(const FeatureMap& other);  // deep copy
    FeatureMap(FeatureMap&& other) noexcept { swap(other); }
    ~FeatureMap();
    FeatureMap& operator=(FeatureMap&& other) noexcept {
        FeatureMap moved;
        moved.swap(other);
        swap(moved);
        return *this;
    }
    void swap(FeatureMap& other) noexcept {
        std::swap(data_, other.data_);
        std::swap(capacity_, other.capacity_);
        std::swap(height_, other.height_);
        std::swap(width_, other.width_);
        std::swap(channels_, other.channels_);
    }

    // Reallocates only when the new size needs more memory than held; contents undefined.
    void resize(int height, int width, int channels);
    void fill(float value);

    int height() const { return height_; }
    int width() const { return width_; }
    int channels() const { return channels_; }
    std::size_t pixelCount() const { return std::size_t(height_) * std::size_t(width_); }
    std::size_t size() const { return pixelCount() * std::size_t(channels_); }
    bool empty() const { return size() == 0; }
    std::size_t capacity() const { return capacity_; }  // floats held

    float* data() { return data_; }
    const float* data() const { return data_; }
    float* pixel(int y, int x) { return data_ + (std::size_t(y) * width_ + x) * channels_; }
    const float* pixel(int y, int x) const { return data_ + (std::size_t(y) * width_ + x) * channels_; }

private:
    float* data_ = nullptr;  // capacity_ floats from allocateMapMemory (map_memory.h)
    std::size_t capacity_ = 0;
    int height_ = 0, width_ = 0, channels_ = 0;
};

}  // namespace affinity
