#include "network/noise_inputs.h"

#include <algorithm>
#include <cmath>

#include "kernels/luminance.h"

namespace affinity {

void makeNoiseInputs(const FeatureMap& signal, const FeatureMap& meanSquares, int spp, int saturationSpp,
                     float exposure, FeatureMap& noise) {
    const int height = signal.height(), width = signal.width();
    noise.resize(height, width, kNoiseInputChannels);
    const float count = std::log2(float(std::max(1, std::min(spp, saturationSpp)))) * kNoiseCountScale;
    // var(mean) = (E[y²] - E[y]²) / (spp - 1), the unbiased sample variance over spp.
    const float perSample = spp > 1 ? 1.0f / float(spp - 1) : 0.0f;
    const float floorSquared = kNoiseLuminanceFloor * kNoiseLuminanceFloor / (exposure * exposure);
    const long long pixels = (long long)height * width;
#pragma omp parallel for schedule(static)
    for (long long p = 0; p < pixels; ++p) {
        const float mean = luminance(signal.data() + std::size_t(p) * 3);
        const float variance = std::max(0.0f, meanSquares.data()[p] - mean * mean) * perSample;
        float* out = noise.data() + std::size_t(p) * kNoiseInputChannels;
        out[0] = count;
        out[1] = std::log1p(variance / (mean * mean + floorSquared));
    }
}

}  // namespace affinity
