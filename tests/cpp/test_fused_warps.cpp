// The fused CPU warps (training/fused_warps.h) against the ATen forms of affinity_ops.h (those
// are checked against the core and by finite differences in test_torch_model): values and the
// gradient to the previous frame, in double and float, for motion that leaves the image, is
// NaN or infinite; the Catmull-Rom clamp's gradient on hand-worked cases, including the one
// where the fused op deliberately differs (tied bounds); and the same bits on any thread count.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <limits>
#include <string>

#include "affinity/error.h"
#include "affinity_ops.h"
#include "fused_warps.h"

namespace affinity::train {
namespace {

struct Warped {
    torch::Tensor out, gradient;
};

using WarpFunction = torch::Tensor (*)(const torch::Tensor&, const torch::Tensor&);

Warped run(WarpFunction warp, const torch::Tensor& previous, const torch::Tensor& motion,
           const torch::Tensor& weights) {
    const torch::Tensor leaf = previous.detach().clone().set_requires_grad(true);
    const torch::Tensor out = warp(leaf, motion);
    (out * weights).sum().backward();
    return {out.detach(), leaf.grad()};
}

// Motion up to `reach` pixels each way, with a few NaN, infinite and far out-of-image vectors.
torch::Tensor awkwardMotion(std::int64_t B, std::int64_t H, std::int64_t W, double reach, torch::Dtype dtype) {
    torch::Tensor motion = (torch::rand({B, 2, H, W}, torch::TensorOptions().dtype(dtype)) - 0.5) * (2 * reach);
    motion[0][0][1][2] = std::numeric_limits<double>::quiet_NaN();
    motion[0][1][3][4] = std::numeric_limits<double>::infinity();
    motion[B - 1][0][2][1] = -std::numeric_limits<double>::infinity();
    motion[B - 1][1][0][0] = 1e6;
    return motion;
}

// Random values, heavy-tailed so that the Catmull-Rom clamp binds on both sides.
torch::Tensor spikyImage(std::int64_t B, std::int64_t C, std::int64_t H, std::int64_t W, torch::Dtype dtype) {
    return torch::randn({B, C, H, W}, torch::TensorOptions().dtype(dtype)).pow(3);
}

double relativeDifference(const torch::Tensor& a, const torch::Tensor& reference) {
    const double scale = std::max(reference.abs().max().item<double>(), 1e-30);
    return (a.to(torch::kDouble) - reference.to(torch::kDouble)).abs().max().item<double>() / scale;
}

void expectSameWarps(torch::Dtype dtype, double tolerance) {
    torch::manual_seed(31);
    for (std::int64_t C : {3, 8}) {
        for (double reach : {0.7, 3.0, 12.0}) {
            const torch::Tensor previous = spikyImage(2, C, 11, 13, dtype);
            const torch::Tensor motion = awkwardMotion(2, 11, 13, reach, dtype);
            const torch::Tensor weights = torch::randn({2, C, 11, 13}, torch::TensorOptions().dtype(dtype));
            const std::string what = std::to_string(C) + " channels, reach " + std::to_string(reach);
            const Warped fusedB = run(fusedWarpBilinear, previous, motion, weights);
            const Warped atenB = run(warpBilinearUnfused, previous, motion, weights);
            EXPECT_LT(relativeDifference(fusedB.out, atenB.out), tolerance) << "bilinear, " << what;
            EXPECT_LT(relativeDifference(fusedB.gradient, atenB.gradient), tolerance) << "bilinear gradient, " << what;
            const Warped fusedC = run(fusedWarpCatmullRom, previous, motion, weights);
            const Warped atenC = run(warpCatmullRomUnfused, previous, motion, weights);
            EXPECT_LT(relativeDifference(fusedC.out, atenC.out), tolerance) << "catmull-rom, " << what;
            EXPECT_LT(relativeDifference(fusedC.gradient, atenC.gradient), tolerance)
                << "catmull-rom gradient, " << what;
        }
    }
}

TEST(FusedWarps, AreTheAtenFormsInDouble) { expectSameWarps(torch::kDouble, 1e-12); }
TEST(FusedWarps, AreTheAtenFormsInFloat) { expectSameWarps(torch::kFloat, 1e-6); }

// Hand-worked cases of the clamp on a row [1, 0, b, b, b], pixel 1 looking half a pixel right:
// taps 1, 0, b, b at weights -1/16, 9/16, 9/16, -1/16 give the spline -1/16 + b / 2, below the
// nearest taps' minimum 0 for b < 1/8, so the output is 0 and its gradient goes to that minimum:
// pixel 1 (it is min(pixel 1, pixel 2) in both tap rows of this one-row image).
TEST(FusedWarps, CatmullRomGradientFollowsTheClampToTheNearestMinimum) {
    torch::Tensor motion = torch::zeros({1, 2, 1, 5}, torch::kDouble);
    motion[0][0][0][1] = 0.5;
    torch::Tensor weights = torch::zeros({1, 1, 1, 5}, torch::kDouble);
    weights[0][0][0][1] = 1.0;
    const torch::Tensor previous = torch::tensor({1.0, 0.0, 0.1, 0.1, 0.1}, torch::kDouble).view({1, 1, 1, 5});
    const torch::Tensor expected = torch::tensor({0.0, 1.0, 0.0, 0.0, 0.0}, torch::kDouble).view({1, 1, 1, 5});
    for (WarpFunction warp : {fusedWarpCatmullRom, warpCatmullRomUnfused}) {
        const Warped w = run(warp, previous, motion, weights);
        EXPECT_EQ(w.out[0][0][0][1].item<double>(), 0.0);
        EXPECT_TRUE(torch::allclose(w.gradient, expected, 0, 1e-15)) << w.gradient;
    }
    // b = 0: the four nearest taps tie, and the minimum's gradient is split between them (pixels
    // 1 and 2 a half each). ATen's clamp backward gives no gradient at all where its bounds are
    // equal; the fused warp keeps the subgradient, so here (and only here) the two differ.
    const torch::Tensor flat = torch::tensor({1.0, 0.0, 0.0, 0.0, 0.0}, torch::kDouble).view({1, 1, 1, 5});
    const Warped w = run(fusedWarpCatmullRom, flat, motion, weights);
    EXPECT_EQ(w.out[0][0][0][1].item<double>(), 0.0);
    EXPECT_TRUE(torch::equal(w.gradient, torch::tensor({0.0, 0.5, 0.5, 0.0, 0.0}, torch::kDouble).view({1, 1, 1, 5})))
        << w.gradient;
}

TEST(FusedWarps, GiveTheSameBitsOnOneAndTwoThreads) {
    torch::manual_seed(32);
    const torch::Tensor previous = torch::randn({3, 5, 17, 19});
    const torch::Tensor motion = awkwardMotion(3, 17, 19, 4.0, torch::kFloat);
    const torch::Tensor weights = torch::randn({3, 5, 17, 19});
    const int threads = torch::get_num_threads();
    for (WarpFunction warp : {fusedWarpBilinear, fusedWarpCatmullRom}) {
        torch::set_num_threads(1);
        const Warped one = run(warp, previous, motion, weights);
        torch::set_num_threads(2);
        const Warped two = run(warp, previous, motion, weights);
        EXPECT_TRUE(torch::equal(one.out, two.out));
        EXPECT_TRUE(torch::equal(one.gradient, two.gradient));
    }
    torch::set_num_threads(threads);
}

TEST(FusedWarps, StepAsideWhereMotionNeedsAGradientAndRejectWhatTheyCannotTake) {
    const torch::Tensor previous = torch::randn({1, 3, 5, 6});
    const torch::Tensor motion = torch::rand({1, 2, 5, 6}).set_requires_grad(true);
    EXPECT_FALSE(fusedWarpApplies(previous, motion));
    EXPECT_TRUE(fusedWarpApplies(previous, motion.detach()));
    EXPECT_FALSE(fusedWarpApplies(previous, motion.detach().to(torch::kDouble)));
    EXPECT_FALSE(fusedWarpApplies(previous, torch::rand({1, 2, 5, 7})));
    EXPECT_THROW(fusedWarpBilinear(previous, torch::rand({1, 3, 5, 6})), Error);
    // warpBilinear then takes the ATen form: motion gets its gradient.
    warpBilinear(previous, motion).sum().backward();
    EXPECT_TRUE(motion.grad().defined());
}

}  // namespace
}  // namespace affinity::train
