#include "affinity/frame.h"

#include "affinity/error.h"

namespace affinity {

SampleFrame::SampleFrame(int width, int height, int spp, bool withReference)
    : SampleFrame(width, height, spp, withReference, true) {}

SampleFrame SampleFrame::withoutSamples(int width, int height, int spp, bool withReference) {
    return SampleFrame(width, height, spp, withReference, false);
}

SampleFrame::SampleFrame(int width, int height, int spp, bool withReference, bool withSamples)
    : width_(width), height_(height), spp_(spp) {
    if (width < 1 || height < 1) {
        throw Error("frame size " + std::to_string(width) + "x" + std::to_string(height) +
                    " is invalid: both sides must be at least 1");
    }
    if (spp < 1 || spp > kMaxSpp) {
        throw Error("samples per pixel " + std::to_string(spp) + " is outside 1.." + std::to_string(kMaxSpp));
    }
    if (withSamples) samples_.assign(pixelCount() * spp * kFeatureCount, 0.0f);
    motion_.assign(pixelCount() * 2, 0.0f);
    valid_.assign(pixelCount(), 0.0f);
    if (withReference) reference_.assign(pixelCount() * 3, 0.0f);
}

SampleFrameView SampleFrame::view(const std::string& user) const {
    if (width_ < 1 || height_ < 1 || spp_ < 1) throw Error(user + ": the frame is empty");
    if (samples_.size() != pixelCount() * std::size_t(spp_) * kFeatureCount || motion_.size() != pixelCount() * 2 ||
        valid_.size() != pixelCount())
        throw Error(user + ": the frame's buffers do not match its size " + std::to_string(width_) + "x" +
                    std::to_string(height_) + " at " + std::to_string(spp_) + " spp");
    return SampleFrameView{width_, height_, spp_, samples_.data(), motion_.data(), valid_.data(), info};
}

std::vector<float> SampleFrame::meanRadiance() const {
    return affinity::meanRadiance({SampleBand{0, height_, const_cast<float*>(samples_.data())}}, width_, height_, spp_);
}

std::vector<float> meanRadiance(const std::vector<SampleBand>& bands, int width, int height, int spp) {
    std::vector<float> mean(std::size_t(width) * std::size_t(height) * 3, 0.0f);
    const float scale = 1.0f / float(spp);
    for (const SampleBand& band : bands) {
        const float* f = band.samples;
        float* out = mean.data() + std::size_t(band.firstRow) * std::size_t(width) * 3;
        for (std::size_t p = 0; p < std::size_t(band.rows) * std::size_t(width); ++p, out += 3) {
            for (int s = 0; s < spp; ++s, f += kFeatureCount)
                for (int c = 0; c < 3; ++c) out[c] += f[channel::kDiffuse + c] + f[channel::kSpecular + c];
            for (int c = 0; c < 3; ++c) out[c] *= scale;
        }
    }
    return mean;
}

}  // namespace affinity
