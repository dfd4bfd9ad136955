#include "affinity/metrics.h"

#include <cmath>
#include <limits>

namespace affinity {

double smape(const float* image, const float* reference, std::size_t n) {
    double sum = 0.0;
    for (std::size_t i = 0; i < n; ++i)
        sum += std::abs(double(image[i]) - reference[i]) / (std::abs(double(image[i])) + std::abs(double(reference[i])) + 0.01);
    return n ? sum / double(n) : 0.0;
}

double relativeMse(const float* image, const float* reference, std::size_t n) {
    double sum = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        double d = double(image[i]) - reference[i];
        sum += d * d / (double(reference[i]) * reference[i] + 0.01);
    }
    return n ? 0.5 * sum / double(n) : 0.0;
}

double tonemappedPsnr(const float* image, const float* reference, std::size_t n) {
    auto tonemap = [](double x) { x = std::max(x, 0.0); return x / (1.0 + x); };
    double sum = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        double d = tonemap(image[i]) - tonemap(reference[i]);
        sum += d * d;
    }
    if (n == 0 || sum == 0.0) return std::numeric_limits<double>::infinity();
    return -10.0 * std::log10(sum / double(n));
}

}  // namespace affinity
