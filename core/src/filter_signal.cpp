#include "filter_signal.h"

#include <algorithm>
#include <string>

#include "affinity/error.h"
#include "embedding.h"

namespace affinity {

void makeFilterSignal(const FeatureMap& sums, int spp, bool albedoDemodulation, FeatureMap& signal,
                      FeatureMap& albedo) {
    if (sums.channels() != Embedding::kSampleSumChannels || spp < 1)
        throw Error("filter signal: needs " + std::to_string(Embedding::kSampleSumChannels) +
                    " sums over at least one sample");
    const int height = sums.height(), width = sums.width();
    signal.resize(height, width, albedoDemodulation ? 6 : 3);
    if (albedoDemodulation) albedo.resize(height, width, 3);
    const long long pixels = (long long)height * width;
    const float count = float(spp);
    const int channels = signal.channels();
#pragma omp parallel for schedule(static)
    for (long long p = 0; p < pixels; ++p) {
        const float* sum = sums.data() + std::size_t(p) * Embedding::kSampleSumChannels;
        float* out = signal.data() + std::size_t(p) * channels;
        if (!albedoDemodulation) {
            for (int c = 0; c < 3; ++c) out[c] = (sum[c] + sum[3 + c]) / count;
            continue;
        }
        float* a = albedo.data() + std::size_t(p) * 3;
        for (int c = 0; c < 3; ++c) {
            a[c] = sum[6 + c] / count;
            out[c] = (sum[c] / count) / std::max(a[c], kDemodulationFloor);
            out[3 + c] = sum[3 + c] / count;
        }
    }
}

void radianceFromSignal(const FeatureMap& signal, const FeatureMap& albedo, float* out) {
    const long long pixels = (long long)signal.pixelCount();
    if (signal.channels() == 3) {
        std::copy(signal.data(), signal.data() + signal.size(), out);
        return;
    }
    if (signal.channels() != 6 || albedo.height() != signal.height() || albedo.width() != signal.width() ||
        albedo.channels() != 3)
        throw Error("filter signal: a demodulated signal needs 6 channels and the frame's 3-channel albedo");
#pragma omp parallel for schedule(static)
    for (long long p = 0; p < pixels; ++p) {
        const float* s = signal.data() + std::size_t(p) * 6;
        const float* a = albedo.data() + std::size_t(p) * 3;
        for (int c = 0; c < 3; ++c) out[std::size_t(p) * 3 + c] = std::max(a[c], kDemodulationFloor) * s[c] + s[3 + c];
    }
}

}  // namespace affinity
