#include "pipeline/history_guard.h"

#include "kernels/luminance.h"

namespace affinity {

float historyGuardFloor(const FeatureMap& signal) {
    const std::size_t pixels = signal.pixelCount();
    if (pixels == 0) return 0.0f;
    double sum = 0.0;
    for (std::size_t p = 0; p < pixels; ++p) sum += luminance(signal.data() + p * signal.channels());
    return kHistoryGuardFloorShare * float(sum / double(pixels));
}

}  // namespace affinity
