#include "network/filter_signal.h"

#include <algorithm>
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

void sampleMeansFromSums(const float* sums, long long pixels, int spp, int sum, float* means) {
    // Larger values (radiance near kMaxRadiance, whose squares overflow) are kept at this: the box
    // sums of the stage that reads them run in double, and an infinity would not leave them.
    constexpr float kLargest = 1e30f;
    const float count = float(spp);
    for (long long p = 0; p < pixels; ++p) {
        const float mean = sums[std::size_t(p) * Embedding::kSampleSumChannels + std::size_t(sum)] / count;
        means[p] = std::min(mean, kLargest);  // (min of +Inf and kLargest is kLargest)
    }
}

void makeSampleMeans(const FeatureMap& sums, int spp, int sum, FeatureMap& means) {
    if (sums.channels() != Embedding::kSampleSumChannels || spp < 1 || sum < 0 || sum >= Embedding::kSampleSumChannels)
        throw Error("sample means: needs " + std::to_string(Embedding::kSampleSumChannels) +
                    " sums over at least one sample, and one of them");
    means.resize(sums.height(), sums.width(), 1);
    const int width = sums.width();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < sums.height(); ++y) sampleMeansFromSums(sums.pixel(y, 0), width, spp, sum, means.pixel(y, 0));
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
