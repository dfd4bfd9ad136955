// The error metrics of docs/BENCHMARK.md, "Metrics" (affinity/metrics.h), on small images whose
// values are worked out by hand in the comments.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "affinity/metrics.h"

namespace affinity {
namespace {

constexpr double kTolerance = 1e-6;

TEST(Metrics, SmapeByHand) {
    // |1-0|/(1+0+0.01) + |0-0|/0.01 + |2-1|/(2+1+0.01), over 3 values.
    const std::vector<float> image{1.0f, 0.0f, 2.0f}, reference{0.0f, 0.0f, 1.0f};
    EXPECT_NEAR(smape(image.data(), reference.data(), 3), (1.0 / 1.01 + 1.0 / 3.01) / 3.0, kTolerance);
    EXPECT_EQ(smape(image.data(), image.data(), 3), 0.0);
    EXPECT_EQ(smape(image.data(), reference.data(), 0), 0.0);
}

TEST(Metrics, RelativeMseByHand) {
    // 0.5 * ((1-0)^2/(0+0.01) + (3-1)^2/(1+0.01)) / 2 = 0.5 * (100 + 3.960396) / 2.
    const std::vector<float> image{1.0f, 3.0f}, reference{0.0f, 1.0f};
    EXPECT_NEAR(relativeMse(image.data(), reference.data(), 2), 0.25 * (100.0 + 4.0 / 1.01), kTolerance);
}

TEST(Metrics, TonemappedPsnrByHand) {
    // x/(1+x): 1 -> 0.5 and 0 -> 0, so the MSE over {1, 0} vs {0, 0} is 0.25/2 = 0.125.
    const std::vector<float> image{1.0f, 0.0f}, reference{0.0f, 0.0f};
    EXPECT_NEAR(tonemappedPsnr(image.data(), reference.data(), 2), -10.0 * std::log10(0.125), kTolerance);
    // Negative values tone-map as 0.
    const std::vector<float> negative{-5.0f, 0.0f};
    EXPECT_TRUE(std::isinf(tonemappedPsnr(negative.data(), reference.data(), 2)));
}

// A 3x1 sequence: the previous output is (1, 3, 5) per pixel (all channels), the current output
// 2 everywhere, and every pixel moved half a pixel right, so frame t sees at pixel x what frame
// t-1 had at x + 0.5. Warped previous output: 2 at x=0, 4 at x=1; x=2's target 2.5 is outside.
struct HalfPixelSequence {
    std::vector<float> previousOutput{1, 1, 1, 3, 3, 3, 5, 5, 5};
    std::vector<float> output = std::vector<float>(9, 2.0f);
    std::vector<float> previousReference = std::vector<float>(9, 0.0f);
    std::vector<float> reference = std::vector<float>(9, 0.0f);
    std::vector<float> motion{0.5f, 0.0f, 0.5f, 0.0f, 0.5f, 0.0f};
    std::vector<float> valid{1.0f, 1.0f, 1.0f};

    double error() const {
        return temporalError(output.data(), previousOutput.data(), reference.data(), previousReference.data(),
                             motion.data(), valid.data(), 3, 1);
    }
};

TEST(Metrics, TemporalErrorAgainstAStaticReference) {
    // x=0: |2 - 2| = 0, x=1: |2 - 4| = 2, x=2 excluded: (0 * 3 + 2 * 3) / 6.
    EXPECT_NEAR(HalfPixelSequence().error(), 1.0, kTolerance);
}

TEST(Metrics, TemporalErrorSubtractsTheReferencesOwnChange) {
    HalfPixelSequence s;
    // The reference brightens by 1 at x=1 in red only: x=1 red becomes |(2-4) - (1-0)| = 3.
    s.reference[3] = 1.0f;
    EXPECT_NEAR(s.error(), (0.0 * 3 + 3.0 + 2.0 + 2.0) / 6.0, kTolerance);
    // An output that changes exactly as the reference does has no temporal error.
    s.output = s.reference;
    s.previousOutput = s.previousReference;
    EXPECT_NEAR(s.error(), 0.0, kTolerance);
}

TEST(Metrics, TemporalErrorSkipsInvalidPixelsAndTargetsOutsideTheImage) {
    HalfPixelSequence s;
    s.valid[0] = 0.0f;  // only x=1 is left: |2 - 4| = 2
    EXPECT_NEAR(s.error(), 2.0, kTolerance);
    s.motion[2] = -1.5f;  // x=1 now looks at -0.5: outside
    EXPECT_TRUE(std::isnan(s.error()));
    s.motion[2] = std::nanf("");
    EXPECT_TRUE(std::isnan(s.error()));
}

TEST(Metrics, TemporalErrorWarpsVertically) {
    // 1x2 column: the lower pixel (y=1) saw, one frame earlier, what is now above it (y=0).
    // Previous output (0, 10), current (0, 4): y=1 compares 4 with warped 0 -> 4; y=0 looks at
    // y=-1, outside. Reference static at 0.
    const std::vector<float> previousOutput{0, 0, 0, 10, 10, 10}, output{0, 0, 0, 4, 4, 4};
    const std::vector<float> zeros(6, 0.0f), motion{0.0f, -1.0f, 0.0f, -1.0f}, valid{1.0f, 1.0f};
    EXPECT_NEAR(temporalError(output.data(), previousOutput.data(), zeros.data(), zeros.data(), motion.data(),
                              valid.data(), 1, 2),
                4.0, kTolerance);
}

double warpingErrorOf(const HalfPixelSequence& s) {
    return warpingError(s.output.data(), s.previousOutput.data(), s.motion.data(), s.valid.data(), 3, 1);
}

TEST(Metrics, WarpingErrorTonemapsBeforeTheWarp) {
    // Tone-mapped previous output (1/2, 3/4, 5/6); warped: x=0 (1/2 + 3/4)/2 = 5/8, x=1
    // (3/4 + 5/6)/2 = 19/24; x=2 is outside. Current output 2 tone-maps to 2/3. Per pixel the
    // squared difference summed over 3 channels: x=0 3 (1/24)^2, x=1 3 (1/8)^2; mean of the two.
    // (Warping the linear image first would give x=0 no change at all.)
    const double expected = (3.0 / (24.0 * 24.0) + 3.0 / 64.0) / 2.0;
    EXPECT_NEAR(warpingErrorOf(HalfPixelSequence()), expected, 1e-7);
}

TEST(Metrics, WarpingErrorNeedsNoReferenceAndCountsLikeTheTemporalError) {
    HalfPixelSequence s;
    s.previousOutput = std::vector<float>(9, 2.0f);  // no change where the warp looks
    EXPECT_NEAR(warpingErrorOf(s), 0.0, 1e-12);
    s.previousOutput = std::vector<float>(9, -3.0f);  // negatives tone-map as 0
    s.output = std::vector<float>(9, 0.0f);
    EXPECT_NEAR(warpingErrorOf(s), 0.0, 1e-12);
    HalfPixelSequence invalid;
    invalid.valid[1] = 0.0f;  // only x=0 is left: 3 (1/24)^2
    EXPECT_NEAR(warpingErrorOf(invalid), 3.0 / (24.0 * 24.0), 1e-7);
    invalid.valid[0] = 0.0f;
    EXPECT_TRUE(std::isnan(warpingErrorOf(invalid)));
}

}  // namespace
}  // namespace affinity
