#include "filter_signal.h"

#include <algorithm>
#include <string>

#include "affinity/error.h"
#include "embedding.h"

namespace affinity {

void makeAccumulatedSignal(const FeatureMap& sums, int spp, bool albedoDemodulation, FeatureMap& signal) {
    if (sums.channels() != Embedding::kSampleSumChannels || spp < 1)
        throw Error("filter signal: needs " + std::to_string(Embedding::kSampleSumChannels) +
                    " sums over at least one sample");
    signal.resize(sums.height(), sums.width(), albedoDemodulation ? 9 : 3);
    const long long pixels = (long long)sums.pixelCount();
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
        for (int c = 0; c < 3; ++c) {
            const float albedo = sum[6 + c] / count;
            out[c] = (sum[c] / count) / std::max(albedo, kDemodulationFloor);
            out[3 + c] = sum[3 + c] / count;
            out[6 + c] = albedo;
        }
    }
}

void splitAccumulatedSignal(const FeatureMap& accumulated, FeatureMap& filtered, FeatureMap& albedo) {
    const int channels = accumulated.channels();
    if (channels != 3 && channels != 9)
        throw Error("filter signal: an accumulated signal has 3 or 9 channels, not " + std::to_string(channels));
    const int kept = channels == 9 ? 6 : 3;
    filtered.resize(accumulated.height(), accumulated.width(), kept);
    if (channels == 9) albedo.resize(accumulated.height(), accumulated.width(), 3);
    const long long pixels = (long long)accumulated.pixelCount();
#pragma omp parallel for schedule(static)
    for (long long p = 0; p < pixels; ++p) {
        const float* in = accumulated.data() + std::size_t(p) * channels;
        std::copy(in, in + kept, filtered.data() + std::size_t(p) * kept);
        if (channels == 9) std::copy(in + 6, in + 9, albedo.data() + std::size_t(p) * 3);
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
