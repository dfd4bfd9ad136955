#include "network/filter_signal.h"

#include <algorithm>
#include <string>

#include "affinity/error.h"
#include "network/embedding.h"

namespace affinity {

void signalFromSums(const float* sums, long long pixels, int spp, const SignalLayout& layout, float* signal) {
    const float count = float(spp);
    const int channels = layout.channels();
    for (long long p = 0; p < pixels; ++p) {
        const float* sum = sums + std::size_t(p) * Embedding::kSampleSumChannels;
        const float* diffuse = sum + Embedding::kSumDiffuse;
        const float* specular = sum + Embedding::kSumSpecular;
        const float* emittedDiffuse = sum + Embedding::kSumEmittedDiffuse;
        const float* emittedSpecular = sum + Embedding::kSumEmittedSpecular;
        float* out = signal + std::size_t(p) * channels;
        for (int c = 0; c < 3; ++c) {
            // Without bypass the emissive samples' light is filtered with the rest.
            const float d = layout.emissionBypass ? diffuse[c] : diffuse[c] + emittedDiffuse[c];
            const float s = layout.emissionBypass ? specular[c] : specular[c] + emittedSpecular[c];
            if (layout.albedoDemodulation) {
                const float albedo = sum[Embedding::kSumAlbedo + c] / count;
                out[c] = (d / count) / std::max(albedo, kDemodulationFloor);
                out[3 + c] = s / count;
                out[6 + c] = albedo;
            } else {
                out[c] = (d + s) / count;
            }
            if (layout.emissionBypass) out[channels - 3 + c] = (emittedDiffuse[c] + emittedSpecular[c]) / count;
        }
    }
}

void makeAccumulatedSignal(const FeatureMap& sums, int spp, const SignalLayout& layout, FeatureMap& signal) {
    if (sums.channels() != Embedding::kSampleSumChannels || spp < 1)
        throw Error("filter signal: needs " + std::to_string(Embedding::kSampleSumChannels) +
                    " sums over at least one sample");
    signal.resize(sums.height(), sums.width(), layout.channels());
    const int width = sums.width();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < sums.height(); ++y)
        signalFromSums(sums.pixel(y, 0), width, spp, layout, signal.pixel(y, 0));
}

void radianceFromSignal(const FeatureMap& filtered, const FeatureMap& accumulated, const SignalLayout& layout,
                        float* out) {
    const int kept = layout.filteredChannels(), channels = layout.channels();
    if (filtered.channels() != kept || accumulated.channels() != channels ||
        accumulated.height() != filtered.height() || accumulated.width() != filtered.width())
        throw Error("filter signal: radiance needs a filtered signal of " + std::to_string(kept) +
                    " channels and an accumulated one of " + std::to_string(channels) + " of the same size");
    const long long pixels = (long long)filtered.pixelCount();
#pragma omp parallel for schedule(static)
    for (long long p = 0; p < pixels; ++p) {
        const float* f = filtered.data() + std::size_t(p) * kept;
        const float* u = accumulated.data() + std::size_t(p) * channels + kept;  // the unfiltered channels
        float* o = out + std::size_t(p) * 3;
        for (int c = 0; c < 3; ++c) {
            float radiance = layout.albedoDemodulation ? std::max(u[c], kDemodulationFloor) * f[c] + f[3 + c] : f[c];
            if (layout.emissionBypass) radiance += u[channels - kept - 3 + c];
            o[c] = radiance;
        }
    }
}

}  // namespace affinity
