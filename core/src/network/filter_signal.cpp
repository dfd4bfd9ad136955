#include "network/filter_signal.h"

#include <string>

#include "affinity/error.h"
#include "network/embedding.h"

namespace affinity {

void signalFromSums(const float* sums, long long pixels, int spp, float* signal) {
    const float count = float(spp);
    for (long long p = 0; p < pixels; ++p) {
        const float* sum = sums + std::size_t(p) * Embedding::kSampleSumChannels;
        float* out = signal + std::size_t(p) * kSignalChannels;
        for (int c = 0; c < 3; ++c)
            out[c] = (sum[Embedding::kSumDiffuse + c] + sum[Embedding::kSumSpecular + c]) / count;
    }
}

void makeAccumulatedSignal(const FeatureMap& sums, int spp, FeatureMap& signal) {
    if (sums.channels() != Embedding::kSampleSumChannels || spp < 1)
        throw Error("filter signal: needs " + std::to_string(Embedding::kSampleSumChannels) +
                    " sums over at least one sample");
    signal.resize(sums.height(), sums.width(), kSignalChannels);
    const int width = sums.width();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < sums.height(); ++y) signalFromSums(sums.pixel(y, 0), width, spp, signal.pixel(y, 0));
}

}  // namespace affinity
