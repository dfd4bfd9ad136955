#include "affinity/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "kernels/affinity_filter.h"
#include "kernels/bilinear_warp.h"
#include "kernels/feature_map.h"

namespace affinity {

double smape(const float* image, const float* reference, std::size_t n) {
    double sum = 0.0;
    for (std::size_t i = 0; i < n; ++i)
        sum += std::abs(double(image[i]) - reference[i]) /
               (std::abs(double(image[i])) + std::abs(double(reference[i])) + 0.01);
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

namespace {

// The tone map of tonemappedPsnr and warpingError: negatives clamped to 0, then x / (1 + x).
double tonemap(double x) {
    x = std::max(x, 0.0);
    return x / (1.0 + x);
}

// The mean over the pixels that count in the temporal metrics (valid, and the warp target inside
// the grid of pixel centres, so no bilinear tap is border-clamped; NaN motion never counts) of
// pixelSum(pixel index, warped pixel of `warped`), each pixel worth `valuesPerPixel` values. NaN
// when no pixel counts.
template <class PixelSum>
double meanOverCountedPixels(const FeatureMap& warped, const float* motion, const float* valid, int valuesPerPixel,
                             PixelSum pixelSum) {
    const int width = warped.width(), height = warped.height();
    double sum = 0.0;
    std::size_t count = 0;
    for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) {
            const std::size_t p = std::size_t(y) * std::size_t(width) + std::size_t(x);
            const float targetX = float(x) + motion[2 * p], targetY = float(y) + motion[2 * p + 1];
            const bool inside =
                targetX >= 0.0f && targetX <= float(width - 1) && targetY >= 0.0f && targetY <= float(height - 1);
            if (!(valid[p] >= 0.5f) || !inside) continue;
            sum += pixelSum(p, warped.pixel(y, x));
            count += std::size_t(valuesPerPixel);
        }
    }
    return count ? sum / double(count) : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace

double tonemappedPsnr(const float* image, const float* reference, std::size_t n) {
    double sum = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        double d = tonemap(image[i]) - tonemap(reference[i]);
        sum += d * d;
    }
    if (n == 0 || sum == 0.0) return std::numeric_limits<double>::infinity();
    return -10.0 * std::log10(sum / double(n));
}

double temporalError(const float* output, const float* previousOutput, const float* reference,
                     const float* previousReference, const float* motion, const float* valid, int width, int height) {
    constexpr double kNoPixel = std::numeric_limits<double>::quiet_NaN();
    if (width <= 0 || height <= 0) return kNoPixel;
    // The warp is linear, so W O - W R = W (O - R): one warp of the previous frame's error.
    FeatureMap previousError(height, width, 3);
    for (std::size_t i = 0; i < previousError.size(); ++i)
        previousError.data()[i] = previousOutput[i] - previousReference[i];
    FeatureMap warpedError;
    warpBilinear(previousError, motion, warpedError);
    return meanOverCountedPixels(warpedError, motion, valid, 3, [&](std::size_t p, const float* warped) {
        double sum = 0.0;
        for (int c = 0; c < 3; ++c) {
            const double error = double(output[3 * p + c]) - reference[3 * p + c];
            sum += std::abs(error - double(warped[c]));
        }
        return sum;
    });
}

double warpingError(const float* image, const float* previousImage, const float* motion, const float* valid, int width,
                    int height) {
    constexpr double kNoPixel = std::numeric_limits<double>::quiet_NaN();
    if (width <= 0 || height <= 0) return kNoPixel;
    // Tone-mapped before the warp: the flicker a viewer sees between the displayed frames.
    FeatureMap previous(height, width, 3);
    for (std::size_t i = 0; i < previous.size(); ++i) previous.data()[i] = float(tonemap(previousImage[i]));
    FeatureMap warped;
    warpBilinear(previous, motion, warped);
    return meanOverCountedPixels(warped, motion, valid, 1, [&](std::size_t p, const float* before) {
        double sum = 0.0;
        for (int c = 0; c < 3; ++c) {
            // Rounded to float like the warped side, so an unchanged still image gives exactly 0.
            const double change = double(float(tonemap(image[3 * p + c]))) - double(before[c]);
            sum += change * change;
        }
        return sum;
    });
}

}  // namespace affinity
