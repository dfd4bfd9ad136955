// The fused affinity-filter op (training/fused_affinity_filter.h) against the same kernels in
// ATen ops (affinityFilterUnfused, itself checked against the formulas and by finite
// differences in test_torch_model): outputs and the gradients of every input, in double and
// float, with and without temporal taps, on batches of odd-sized images
// with taps reaching past the border; and the same bits on any thread count.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <string>
#include <vector>

#include "affinity/error.h"
#include "affinity_ops.h"
#include "fused_affinity_filter.h"

namespace affinity::train {
namespace {

struct Case {
    torch::Tensor radiance;
    KernelParams kernel;
    TemporalTaps temporal;
    torch::Tensor lossWeights;  // the loss is sum(out * lossWeights)
};

torch::Tensor leaf(const torch::Tensor& t) { return t.detach().clone().contiguous().set_requires_grad(true); }

Case randomCase(torch::Dtype dtype, std::int64_t B, std::int64_t C, std::int64_t F, std::int64_t H, std::int64_t W) {
    const auto o = torch::TensorOptions().dtype(dtype);
    Case c;
    c.radiance = torch::rand({B, C, H, W}, o) * 3;
    c.kernel = {torch::randn({B, F, H, W}, o) * 0.5, torch::randn({B, 1, H, W}, o), torch::rand({B, 1, H, W}, o)};
    c.temporal = {torch::randn({B, 1, H, W}, o), torch::rand({B, C, H, W}, o) * 3, torch::randn({B, F, H, W}, o) * 0.5,
                  (torch::rand({B, 1, H, W}, o) < 0.7).to(dtype)};
    c.lossWeights = torch::randn({B, C, H, W}, o);
    return c;
}

// Fresh leaves of a case: each implementation gets its own gradients.
Case leaves(const Case& c) {
    Case l = c;
    l.radiance = leaf(c.radiance);
    l.kernel = {leaf(c.kernel.features), leaf(c.kernel.bandwidth), leaf(c.kernel.centre)};
    l.temporal = {leaf(c.temporal.bandwidth), leaf(c.temporal.output), leaf(c.temporal.features), c.temporal.valid};
    return l;
}

struct Result {
    torch::Tensor out;
    std::vector<std::pair<std::string, torch::Tensor>> gradients;
};

Result run(const Case& c, bool fused, bool temporal, int tapSize, int dilation) {
    Case l = leaves(c);
    const TemporalTaps* taps = temporal ? &l.temporal : nullptr;
    const torch::Tensor out = fused ? fusedAffinityFilter(l.radiance, l.kernel, tapSize, dilation, taps)
                                    : affinityFilterUnfused(l.radiance, l.kernel, tapSize, dilation, taps);
    (out * c.lossWeights).sum().backward();
    Result r{out.detach(), {}};
    r.gradients = {{"radiance", l.radiance.grad()},
                   {"features", l.kernel.features.grad()},
                   {"bandwidth", l.kernel.bandwidth.grad()},
                   {"centre", l.kernel.centre.grad()}};
    if (temporal) {
        r.gradients.push_back({"temporal bandwidth", l.temporal.bandwidth.grad()});
        r.gradients.push_back({"warped output", l.temporal.output.grad()});
        r.gradients.push_back({"warped features", l.temporal.features.grad()});
    }
    return r;
}

// Largest difference relative to the reference's largest magnitude.
double relativeDifference(const torch::Tensor& a, const torch::Tensor& reference) {
    const double scale = reference.abs().max().item<double>();
    return (a.to(torch::kDouble) - reference.to(torch::kDouble)).abs().max().item<double>() / std::max(scale, 1e-30);
}

void expectSameFunction(torch::Dtype dtype, double tolerance) {
    torch::manual_seed(21);
    for (std::int64_t C : {3, 6}) {
        const Case c = randomCase(dtype, 2, C, 5, 9, 11);
        for (int dilation : {1, 2, 4, 8}) {
            for (bool temporal : {false, true}) {
                const std::string what = std::to_string(C) + " channels, dilation " + std::to_string(dilation) +
                                         (temporal ? ", temporal" : "");
                const Result fused = run(c, true, temporal, 5, dilation);
                const Result aten = run(c, false, temporal, 5, dilation);
                EXPECT_LT(relativeDifference(fused.out, aten.out), tolerance) << what;
                ASSERT_EQ(fused.gradients.size(), aten.gradients.size());
                for (std::size_t i = 0; i < fused.gradients.size(); ++i) {
                    ASSERT_TRUE(fused.gradients[i].second.defined()) << what << ": " << fused.gradients[i].first;
                    // A gradient that is all zero would make the comparison empty.
                    EXPECT_GT(aten.gradients[i].second.abs().max().item<double>(), 1e-3)
                        << what << ": " << aten.gradients[i].first;
                    EXPECT_LT(relativeDifference(fused.gradients[i].second, aten.gradients[i].second), tolerance)
                        << what << ": " << fused.gradients[i].first;
                }
            }
        }
    }
}

TEST(FusedAffinityFilter, IsTheAtenFormInDouble) { expectSameFunction(torch::kDouble, 1e-12); }

// Float: the fused op's exponential is the core's polynomial (relative error about 2e-7).
TEST(FusedAffinityFilter, IsTheAtenFormInFloat) { expectSameFunction(torch::kFloat, 2e-5); }

TEST(FusedAffinityFilter, GivesTheSameBitsOnOneAndTwoThreads) {
    torch::manual_seed(22);
    const Case c = randomCase(torch::kFloat, 3, 3, 8, 37, 23);
    const int threads = torch::get_num_threads();
    torch::set_num_threads(1);
    const Result one = run(c, true, true, 5, 2);
    torch::set_num_threads(2);
    const Result two = run(c, true, true, 5, 2);
    torch::set_num_threads(threads);
    EXPECT_TRUE(torch::equal(one.out, two.out));
    for (std::size_t i = 0; i < one.gradients.size(); ++i)
        EXPECT_TRUE(torch::equal(one.gradients[i].second, two.gradients[i].second)) << one.gradients[i].first;
}

TEST(FusedAffinityFilter, RejectsMismatchedInputs) {
    const Case c = randomCase(torch::kFloat, 1, 3, 4, 6, 7);
    KernelParams wrongSize = c.kernel;
    wrongSize.bandwidth = torch::rand({1, 1, 6, 8});
    EXPECT_THROW(fusedAffinityFilter(c.radiance, wrongSize, 5, 1, nullptr), Error);
    KernelParams wrongType = c.kernel;
    wrongType.centre = wrongType.centre.to(torch::kDouble);
    EXPECT_THROW(fusedAffinityFilter(c.radiance, wrongType, 5, 1, nullptr), Error);
    TemporalTaps wrongChannels = c.temporal;
    wrongChannels.output = torch::rand({1, 6, 6, 7});
    EXPECT_THROW(fusedAffinityFilter(c.radiance, c.kernel, 5, 1, &wrongChannels), Error);
    EXPECT_THROW(fusedAffinityFilter(c.radiance, c.kernel, 4, 1, nullptr), Error);
    EXPECT_THROW(fusedAffinityFilter(c.radiance, c.kernel, 5, 0, nullptr), Error);
}

}  // namespace
}  // namespace affinity::train
