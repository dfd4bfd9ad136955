#pragma once
// One frame of per-sample render data: every sample's 18 features kept separate, plus the
// per-pixel motion into the previous frame, a history-validity mask, an optional converged
// reference, and the frame's metadata. Producers and consumers all exchange this type.
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "affinity/features.h"

namespace affinity {

// Row-major 4x4 matrix. Points are column vectors: p' = M * p.
using Matrix4 = std::array<float, 16>;

struct FrameInfo {
    std::string sceneName;
    int frameIndex = 0;
    int referenceSpp = 0;  // samples per pixel of `reference`; 0 when there is none
    std::uint64_t seed = 0;
    // World to camera space; the camera looks down -Z with +Y up (OpenGL and Blender convention).
    Matrix4 worldToCamera{};
    // Camera space to clip space (OpenGL perspective). Pixel (px, py), y down, relates to NDC by
    // px = (ndc.x + 1) / 2 * width, py = (1 - ndc.y) / 2 * height.
    Matrix4 cameraToClip{};
};

// A frame's per-pixel inputs without owning them: what the denoiser reads. SampleFrame::view()
// makes one; the Python binding points one at numpy arrays, so a frame is never copied there.
struct SampleFrameView {
    int width = 0, height = 0, spp = 0;
    const float* samples = nullptr;  // [y][x][s][feature], kFeatureCount floats per sample
    const float* motion = nullptr;   // [y][x][2]
    const float* valid = nullptr;    // [y][x]
    FrameInfo info;

    std::size_t pixelCount() const { return std::size_t(width) * std::size_t(height); }
    const float* sample(int x, int y, int s) const {
        return samples + ((std::size_t(y) * std::size_t(width) + std::size_t(x)) * std::size_t(spp) + std::size_t(s)) *
                             kFeatureCount;
    }
};

// Rows [firstRow, firstRow + rows) of a frame's per-sample features, [row][x][s][feature]: a
// frame's samples may be held in several such bands (Denoiser::sampleBands lends them).
struct SampleBand {
    int firstRow = 0, rows = 0;
    float* samples = nullptr;
};

// Per-pixel mean of the samples' radiance (diffuse + specular) of a frame held in bands that
// cover its rows in order: the noisy input, [y][x][3].
std::vector<float> meanRadiance(const std::vector<SampleBand>& bands, int width, int height, int spp);

class SampleFrame {
public:
    SampleFrame() = default;
    // Allocates zeroed buffers; throws affinity::Error for sizes < 1 or spp outside [1, kMaxSpp].
    SampleFrame(int width, int height, int spp, bool withReference);
    // The same without the samples, which live elsewhere (bands; frame_io.h's readFrame):
    // samples() is empty.
    static SampleFrame withoutSamples(int width, int height, int spp, bool withReference);

    static constexpr int kMaxSpp = 64;

    int width() const { return width_; }
    int height() const { return height_; }
    int spp() const { return spp_; }
    std::size_t pixelCount() const { return std::size_t(width_) * std::size_t(height_); }
    bool hasReference() const { return !reference_.empty(); }

    // Features of sample s of pixel (x, y): kFeatureCount floats, see features.h.
    float* sample(int x, int y, int s) { return samples_.data() + sampleOffset(x, y, s); }
    const float* sample(int x, int y, int s) const { return samples_.data() + sampleOffset(x, y, s); }
    // Motion (dx, dy) in pixels: the surface seen at pixel centre (x + 0.5, y + 0.5) was at
    // (x + 0.5 + dx, y + 0.5 + dy) in the previous frame (x right, y down).
    float* motion(int x, int y) { return motion_.data() + 2 * pixelIndex(x, y); }
    const float* motion(int x, int y) const { return motion_.data() + 2 * pixelIndex(x, y); }
    // 1 where the previous frame saw the same surface at the motion target, else 0.
    float& valid(int x, int y) { return valid_[pixelIndex(x, y)]; }
    float valid(int x, int y) const { return valid_[pixelIndex(x, y)]; }
    // Converged linear RGB radiance (diffuse + specular) at referenceSpp.
    float* reference(int x, int y) { return reference_.data() + 3 * pixelIndex(x, y); }
    const float* reference(int x, int y) const { return reference_.data() + 3 * pixelIndex(x, y); }

    // Whole buffers, row-major: samples [y][x][s][feature], motion [y][x][2], valid [y][x],
    // reference [y][x][3] (empty without a reference).
    std::vector<float>& samples() { return samples_; }
    const std::vector<float>& samples() const { return samples_; }
    std::vector<float>& motion() { return motion_; }
    const std::vector<float>& motion() const { return motion_; }
    std::vector<float>& valid() { return valid_; }
    const std::vector<float>& valid() const { return valid_; }
    std::vector<float>& reference() { return reference_; }
    const std::vector<float>& reference() const { return reference_; }

    FrameInfo info;

    // Throws affinity::Error, its message starting with `user`, when the frame is empty or a
    // buffer does not match the frame's size (they are public).
    SampleFrameView view(const std::string& user) const;

    // Per-pixel mean of the samples' radiance (diffuse + specular): the noisy input, [y][x][3].
    std::vector<float> meanRadiance() const;

    std::size_t pixelIndex(int x, int y) const { return std::size_t(y) * width_ + x; }

private:
    SampleFrame(int width, int height, int spp, bool withReference, bool withSamples);
    std::size_t sampleOffset(int x, int y, int s) const { return (pixelIndex(x, y) * spp_ + s) * kFeatureCount; }

    int width_ = 0, height_ = 0, spp_ = 0;
    std::vector<float> samples_, motion_, valid_, reference_;
};

}  // namespace affinity
