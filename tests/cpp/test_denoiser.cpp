// The sequence denoiser's contract: invariances, temporal behaviour, odd sizes, bad input.
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <thread>

#include <gtest/gtest.h>
#include <omp.h>

#include "affinity/denoiser.h"
#include "affinity/error.h"
#include "pipeline/ablation.h"
#include "random_model.h"

using namespace affinity;

namespace {

Model randomModel(unsigned seed = 1, float lambdaBias = 0.0f, float temporalBias = 0.0f) {
    return Model::fromWeights(test::randomWeights(test::ModelShape{}, seed, lambdaBias, temporalBias),
                              Precision::Float32);
}

// A model that cannot see history: lambda = 0, the U-Net's history input channels zeroed and
// (by default) a huge temporal bandwidth, which leaves no weight on the temporal taps (1e6: at
// 1e4, features 3e-4 apart still weighed enough to move an output by 1e-5).
Model historyBlindModel(unsigned seed, float temporalBias = 1e6f) {
    auto tensors = test::randomModelTensors(test::ModelShape{}, seed, -1e4f, temporalBias);
    const int embedding = test::ModelShape{}.embedding.back();
    for (auto& t : tensors)
        if (t.name == "unet.enc0.conv0.weight")
            for (std::int64_t o = 0; o < t.shape[0]; ++o)
                for (std::int64_t i = embedding; i < 2 * embedding; ++i)
                    std::fill_n(t.floats.begin() + (o * t.shape[1] + i) * 9, 9, 0.0f);
    auto bytes = train::serializeWeights(tensors);
    return Model::fromWeights(Weights::fromMemory(bytes.data(), bytes.size(), "history-blind model"),
                              Precision::Float32);
}

double maxRelativeDifference(const std::vector<float>& a, const std::vector<float>& b) {
    EXPECT_EQ(a.size(), b.size());
    double worst = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i)
        worst = std::max(worst, std::abs(double(a[i]) - b[i]) / (std::abs(double(b[i])) + 1e-3));
    return worst;
}

bool allFinite(const std::vector<float>& v) {
    for (float x : v)
        if (!std::isfinite(x)) return false;
    return true;
}

}  // namespace

TEST(Denoiser, ModelStructureComesFromTheWeights) {
    test::ModelShape shape;
    shape.embedding = {24, 12};
    shape.encoder = {6, 10, 14};
    shape.kernels = 2;
    shape.affinityFeatures = 5;
    shape.tapSize = 3;
    Model model = Model::fromWeights(test::randomWeights(shape, 3), Precision::Float32);
    EXPECT_EQ(model.kernels(), 2);
    EXPECT_EQ(model.affinityFeatures(), 5);
    EXPECT_EQ(model.tapSize(), 3);
    EXPECT_EQ(model.embeddingChannels(), 12);
    std::int64_t parameters = 0;
    for (const auto& t : test::randomModelTensors(shape, 3))
        if (t.dtype == DType::Float32) parameters += std::int64_t(t.floats.size());
    EXPECT_EQ(model.parameterCount(), parameters);
    Denoiser denoiser(model);
    auto frames = test::randomSequence(2, 9, 7, 2, 5);
    for (const SampleFrame& f : frames) EXPECT_TRUE(allFinite(denoiser.denoise(f)));
}

TEST(Denoiser, InconsistentWeightsAreRejectedWithTheTensorName) {
    auto tensors = test::randomModelTensors(test::ModelShape{}, 1);
    for (auto& t : tensors)
        if (t.name == "unet.dec0.conv0.weight") {
            t.shape[1] += 1;
            t.floats.resize(t.floats.size() + std::size_t(t.shape[0]) * 9);
        }
    auto bytes = train::serializeWeights(tensors);
    try {
        Model::fromWeights(Weights::fromMemory(bytes.data(), bytes.size(), "bad.affw"));
        FAIL() << "expected an error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("bad.affw"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("unet.dec0.conv0.weight"), std::string::npos) << e.what();
    }
    tensors = test::randomModelTensors(test::ModelShape{}, 1);
    tensors.push_back({"unet.extra.weight", DType::Float32, {1}, {0.0f}, {}});
    bytes = train::serializeWeights(tensors);
    EXPECT_THROW(Model::fromWeights(Weights::fromMemory(bytes.data(), bytes.size(), "extra.affw")), Error);
}

// Switches of variants that were removed (docs/TRAINING.md, "Tried and lost"): a file that turns
// one on is refused with the switch's name instead of being read as a different model; off (0)
// is the model this code computes and loads.
TEST(Denoiser, WeightsWithARemovedSwitchOnAreRefusedNamingIt) {
    for (const char* removed :
         {"config.source_weights", "config.emission_lambda", "config.albedo_demodulation", "config.emission_bypass"}) {
        SCOPED_TRACE(removed);
        test::ModelShape shape;
        auto tensors = test::randomModelTensors(shape, 1);
        tensors.push_back({removed, DType::Int32, {1}, {}, {1}});
        auto bytes = train::serializeWeights(tensors);
        try {
            Model::fromWeights(Weights::fromMemory(bytes.data(), bytes.size(), "old.affw"));
            ADD_FAILURE() << "accepted a model with " << removed << " = 1";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("old.affw"), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find(std::string(removed) + " = 1"), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find("was removed"), std::string::npos) << e.what();
        }
        tensors.back().ints = {0};
        bytes = train::serializeWeights(tensors);
        const Weights off = Weights::fromMemory(bytes.data(), bytes.size(), "off.affw");
        Denoiser withSwitchOff(Model::fromWeights(off, Precision::Float32)),
            plain(Model::fromWeights(test::randomWeights(shape, 1), Precision::Float32));
        for (const SampleFrame& frame : test::randomSequence(2, 9, 7, 2, 5))
            EXPECT_EQ(withSwitchOff.denoise(frame), plain.denoise(frame));
    }
}

TEST(Denoiser, OutputDoesNotDependOnSampleOrder) {
    auto frames = test::randomSequence(3, 16, 12, 4, 9);
    auto permuted = frames;
    for (SampleFrame& f : permuted)
        for (int y = 0; y < f.height(); ++y)
            for (int x = 0; x < f.width(); ++x) {
                // Reverse the samples of every pixel.
                for (int s = 0; s < f.spp() / 2; ++s)
                    std::swap_ranges(f.sample(x, y, s), f.sample(x, y, s) + kFeatureCount,
                                     f.sample(x, y, f.spp() - 1 - s));
            }
    Denoiser a(randomModel(1)), b(randomModel(1));
    for (std::size_t t = 0; t < frames.size(); ++t)
        EXPECT_LT(maxRelativeDifference(a.denoise(frames[t]), b.denoise(permuted[t])), 1e-4) << "frame " << t;
}

TEST(Denoiser, ResetForgetsHistory) {
    auto frames = test::randomSequence(3, 12, 10, 2, 4);
    Denoiser sequence(randomModel()), fresh(randomModel());
    sequence.denoise(frames[0]);
    std::vector<float> withHistory = sequence.denoise(frames[1]);
    std::vector<float> alone = fresh.denoise(frames[1]);
    EXPECT_GT(maxRelativeDifference(withHistory, alone), 1e-3);  // history matters
    sequence.reset();
    DenoiseReport report;
    EXPECT_EQ(sequence.denoise(frames[1], &report), alone);
    EXPECT_FALSE(report.usedHistory);
}

// With lambda = 0 (no accumulation), a huge temporal bandwidth (no temporal taps) and a U-Net
// blind to its history input, frame 2 is denoised exactly as if it were alone.
// The frames with frame 0's radiance, shifted along each row by 5 pixels per frame: a sequence
// keeps the exposure of its first frame (docs/MODEL.md section 1), so a later frame denoised alone
// has the same exposure only if its radiance is frame 0's over every square of the exposure key
// (frames of at most 16x16 pixels are one square). Shifted, so that no pixel's features repeat
// frame 0's (the temporal taps of a history-blind model weigh only exact repeats).
std::vector<SampleFrame> withTheFirstFramesRadiance(std::vector<SampleFrame> frames) {
    for (std::size_t t = 1; t < frames.size(); ++t) {
        const int width = frames[t].width(), shift = int(5 * t) % width;
        EXPECT_LE(std::max(width, frames[t].height()), kExposureBin);
        for (int y = 0; y < frames[t].height(); ++y)
            for (int x = 0; x < width; ++x)
                for (int s = 0; s < frames[t].spp(); ++s)
                    std::copy_n(frames[0].sample((x + shift) % width, y, s) + channel::kDiffuse, 6,
                                frames[t].sample(x, y, s) + channel::kDiffuse);
    }
    return frames;
}

TEST(Denoiser, LambdaZeroEqualsSingleFrameDenoising) {
    auto frames = withTheFirstFramesRadiance(test::randomSequence(2, 12, 10, 2, 6));
    Denoiser sequence(historyBlindModel(2)), single(historyBlindModel(2));
    sequence.denoise(frames[0]);
    EXPECT_LT(maxRelativeDifference(sequence.denoise(frames[1]), single.denoise(frames[1])), 1e-6);
}

// A random model whose first K - 1 kernels are identities: a huge bandwidth leaves weight only
// on the centre tap.
Model identityFirstKernelsModel(unsigned seed) {
    const test::ModelShape shape;
    auto tensors = test::randomModelTensors(shape, seed);
    for (auto& t : tensors)
        if (t.name == "unet.head.bias")
            for (int k = 0; k + 1 < shape.kernels; ++k)
                t.floats[std::size_t(k * (shape.affinityFeatures + 2) + shape.affinityFeatures)] += 1e4f;
    auto bytes = train::serializeWeights(tensors);
    return Model::fromWeights(Weights::fromMemory(bytes.data(), bytes.size(), "identity-first-kernels model"),
                              Precision::Float32);
}

TEST(DenoiserAblation, SingleFrameDenoisesEveryFrameAlone) {
    auto frames = withTheFirstFramesRadiance(test::randomSequence(3, 12, 10, 2, 8));
    Denoiser ablated = ablatedDenoiser(randomModel(), {.useHistory = false});
    Denoiser fresh(randomModel()), full(randomModel());
    ablated.denoise(frames[0]);
    full.denoise(frames[0]);
    DenoiseReport report;
    const std::vector<float> out = ablated.denoise(frames[1], &report);
    EXPECT_EQ(out, fresh.denoise(frames[1]));
    EXPECT_FALSE(report.usedHistory);
    EXPECT_GT(maxRelativeDifference(full.denoise(frames[1]), out), 1e-3);  // the option changed something
}

// Without accumulation, the temporal kernel is the only way history reaches the output: turning
// it off must give exactly the single-frame result, and leaving it on must not.
TEST(DenoiserAblation, NoTemporalKernelRemovesTheOnlyHistoryPathOfANonAccumulatingModel) {
    auto frames = withTheFirstFramesRadiance(test::randomSequence(2, 12, 10, 2, 9));
    Denoiser withKernel(historyBlindModel(3, 0.0f)), single(historyBlindModel(3, 0.0f));
    Denoiser withoutKernel = ablatedDenoiser(historyBlindModel(3, 0.0f), {.temporalKernel = false});
    withKernel.denoise(frames[0]);
    withoutKernel.denoise(frames[0]);
    const std::vector<float> alone = single.denoise(frames[1]);
    EXPECT_LT(maxRelativeDifference(withoutKernel.denoise(frames[1]), alone), 1e-6);
    EXPECT_GT(maxRelativeDifference(withKernel.denoise(frames[1]), alone), 1e-3);
}

// With the first K - 1 kernels being identities, running only the last kernel changes nothing;
// on a random model it does.
TEST(DenoiserAblation, OneKernelSkipsTheDilatedKernelsBeforeTheLast) {
    auto frames = test::randomSequence(2, 12, 10, 2, 10);
    for (int t = 0; t < 2; ++t) {
        Denoiser all(identityFirstKernelsModel(4)), randomAll(randomModel(4));
        Denoiser last = ablatedDenoiser(identityFirstKernelsModel(4), {.allKernels = false});
        Denoiser randomLast = ablatedDenoiser(randomModel(4), {.allKernels = false});
        auto run = [&](Denoiser& denoiser) {  // frame t, after the frames before it
            for (int i = 0; i < t; ++i) denoiser.denoise(frames[std::size_t(i)]);
            return denoiser.denoise(frames[std::size_t(t)]);
        };
        EXPECT_LT(maxRelativeDifference(run(last), run(all)), 1e-5) << "frame " << t;
        EXPECT_GT(maxRelativeDifference(run(randomLast), run(randomAll)), 1e-3) << "frame " << t;
    }
}

TEST(Denoiser, ReportsTheTimeOfEveryStage) {
    auto frames = test::randomSequence(2, 12, 10, 2, 11);
    Denoiser denoiser(randomModel());
    DenoiseReport report;
    denoiser.denoise(frames[0], &report);
    std::vector<std::string> stages;
    for (const auto& [stage, ms] : report.stageMilliseconds) {
        stages.push_back(stage);
        EXPECT_GE(ms, 0.0) << stage;
    }
    ASSERT_EQ(stages.size(), 8u);
    EXPECT_EQ(stages.front(), "embedding");
    EXPECT_EQ(stages[5], "temporal kernel");
    EXPECT_EQ(stages[6], "peak guard");
    EXPECT_EQ(stages.back(), "input fallback");
}

TEST(Denoiser, OddSizesWork) {
    for (auto [w, h] : {std::pair{1, 1}, {7, 13}, {13, 7}, {1, 9}, {17, 3}, {33, 19}}) {
        auto frames = test::randomSequence(2, w, h, 3, unsigned(w * 100 + h));
        Denoiser denoiser(randomModel(1));
        for (const SampleFrame& f : frames) {
            std::vector<float> out = denoiser.denoise(f);
            EXPECT_EQ(out.size(), std::size_t(w) * h * 3);
            EXPECT_TRUE(allFinite(out)) << w << "x" << h;
        }
    }
}

TEST(Denoiser, ResultsDoNotDependOnThreadCount) {
    auto frames = test::randomSequence(2, 21, 15, 2, 8);
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    Denoiser one(randomModel(1));
    std::vector<float> a0 = one.denoise(frames[0]), a1 = one.denoise(frames[1]);
    omp_set_num_threads(std::max(2, threads));
    Denoiser many(randomModel(1));
    std::vector<float> b0 = many.denoise(frames[0]), b1 = many.denoise(frames[1]);
    omp_set_num_threads(threads);
    EXPECT_EQ(a0, b0);
    EXPECT_EQ(a1, b1);
}

TEST(DenoiserBFloat16, ResultsDoNotDependOnThreadCount) {
    if (!bfloat16Supported()) GTEST_SKIP() << "no AVX512-BF16 on this CPU";
    auto frames = test::randomSequence(2, 37, 21, 3, 9);
    const Weights weights = test::randomWeights(test::ModelShape{}, 4);
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    Denoiser one(Model::fromWeights(weights, Precision::BFloat16));
    std::vector<float> a0 = one.denoise(frames[0]), a1 = one.denoise(frames[1]);
    omp_set_num_threads(std::max(2, threads));
    Denoiser many(Model::fromWeights(weights, Precision::BFloat16));
    std::vector<float> b0 = many.denoise(frames[0]), b1 = many.denoise(frames[1]);
    omp_set_num_threads(threads);
    EXPECT_EQ(a0, b0);
    EXPECT_EQ(a1, b1);
    EXPECT_EQ(many.model().precision(), Precision::BFloat16);
}

TEST(DenoiserBFloat16, WithoutTheInstructionsItIsAnErrorThatSaysSo) {
    const Weights weights = test::randomWeights(test::ModelShape{}, 4);
    if (bfloat16Supported()) GTEST_SKIP() << "this CPU has AVX512-BF16";
    try {
        Model::fromWeights(weights, Precision::BFloat16);
        FAIL() << "a bfloat16 model was built on a CPU without AVX512-BF16";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("AVX512-BF16"), std::string::npos) << e.what();
    }
}

TEST(DenoiserBFloat16, PrecisionNamesRoundTripAndOthersAreRejected) {
    EXPECT_EQ(precisionFromName("fp32"), Precision::Float32);
    EXPECT_EQ(precisionFromName("bf16"), Precision::BFloat16);
    EXPECT_EQ(precisionFromName("auto"), Precision::Auto);
    for (Precision p : {Precision::Auto, Precision::Float32, Precision::BFloat16})
        EXPECT_EQ(precisionFromName(precisionName(p)), p);
    EXPECT_STREQ(precisionName(Precision::BFloat16), "bf16");
    EXPECT_THROW(precisionFromName("fp16"), Error);
}

// The default (auto) computes in bfloat16 exactly where the CPU has AVX512-BF16 and in FP32
// elsewhere, for every way to make a model; asking for FP32 overrides it.
TEST(DenoiserPrecision, TheDefaultIsBFloat16ExactlyWhereSupportedAndFp32OverridesIt) {
    const Precision expected = bfloat16Supported() ? Precision::BFloat16 : Precision::Float32;
    EXPECT_EQ(resolvePrecision(Precision::Auto), expected);
    EXPECT_EQ(resolvePrecision(Precision::Float32), Precision::Float32);
    const Weights weights = test::randomWeights(test::ModelShape{}, 4);
    const std::string file = AFFINITY_SOURCE_DIR "/core/models/default.affw";
    EXPECT_EQ(Model::builtIn().precision(), expected);
    EXPECT_EQ(Model::fromFile(file).precision(), expected);
    EXPECT_EQ(Model::fromWeights(weights).precision(), expected);
    EXPECT_EQ(Denoiser().model().precision(), expected);
    EXPECT_EQ(Model::builtIn(Precision::Auto).precision(), expected);
    EXPECT_EQ(Model::builtIn(Precision::Float32).precision(), Precision::Float32);
    EXPECT_EQ(Model::fromFile(file, Precision::Float32).precision(), Precision::Float32);
    EXPECT_EQ(Model::fromWeights(weights, Precision::Float32).precision(), Precision::Float32);
    EXPECT_STREQ(precisionName(Model::builtIn().precision()), bfloat16Supported() ? "bf16" : "fp32");
    // The outputs too: the default's are the resolved precision's, bit for bit.
    auto frames = test::randomSequence(2, 37, 21, 3, 9);
    Denoiser byDefault(Model::fromWeights(weights)), resolved(Model::fromWeights(weights, expected)),
        fp32(Model::fromWeights(weights, Precision::Float32));
    for (const SampleFrame& frame : frames) {
        const std::vector<float> out = byDefault.denoise(frame);
        EXPECT_EQ(out, resolved.denoise(frame));
        if (bfloat16Supported())
            EXPECT_NE(out, fp32.denoise(frame)) << "the default computed in FP32 on a CPU with AVX512-BF16";
        else
            EXPECT_EQ(out, fp32.denoise(frame));
    }
}

TEST(Denoiser, BadRadianceGivesFiniteOutputAndAWarningCount) {
    auto frames = test::randomSequence(2, 10, 8, 2, 3);
    frames[1].sample(2, 3, 0)[channel::kDiffuse] = std::nanf("");
    frames[1].sample(4, 4, 1)[channel::kSpecular + 2] = INFINITY;
    frames[1].sample(5, 1, 0)[channel::kDiffuse + 1] = -3.0f;
    frames[1].sample(0, 0, 1)[channel::kSpecular] = -INFINITY;
    // Bad albedo is not radiance: it reads as 0 where used and is not counted.
    frames[1].sample(6, 2, 0)[channel::kAlbedo] = std::nanf("");
    frames[1].sample(7, 2, 1)[channel::kAlbedo + 1] = -INFINITY;
    Denoiser denoiser(randomModel(1));
    denoiser.denoise(frames[0]);
    DenoiseReport report;
    EXPECT_TRUE(allFinite(denoiser.denoise(frames[1], &report)));
    EXPECT_EQ(report.invalidRadiance, 4);
}

// Issue 42, item 3: four samples of 9e37 each sum past the largest float; once that sum was
// Inf, Inf - Inf spread NaN over a quarter of the frame.
TEST(Denoiser, HugeFiniteRadianceGivesFiniteOutputAndAWarningCount) {
    auto frames = test::randomSequence(2, 12, 10, 4, 5);
    for (int s = 0; s < 4; ++s)
        for (int c = 0; c < 6; ++c) frames[1].sample(3, 4, s)[channel::kDiffuse + c] = 9e37f;
    frames[1].sample(7, 2, 0)[channel::kSpecular + 1] = 3.4e38f;
    Denoiser denoiser(randomModel(2));
    denoiser.denoise(frames[0]);
    DenoiseReport report;
    EXPECT_TRUE(allFinite(denoiser.denoise(frames[1], &report)));
    EXPECT_EQ(report.invalidRadiance, 4 * 6 + 1);
    // A frame whose huge value is its first sets the exposure: the next frame is still finite.
    Denoiser fresh(randomModel(2));
    EXPECT_TRUE(allFinite(fresh.denoise(frames[1])));
    EXPECT_TRUE(allFinite(fresh.denoise(frames[0])));
}

// Issue 42, item 1: two threads on one denoiser crashed or failed with internal errors. Thread
// A is held inside its call (in the interrupt check) while this thread tries the others.
TEST(Denoiser, ASecondCallWhileOneRunsIsRefusedAndTheFirstIsUnharmed) {
    const auto frames = test::randomSequence(1, 12, 10, 2, 6);
    Denoiser denoiser(randomModel(3));
    std::mutex mutex;
    std::condition_variable changed;
    bool inside = false, released = false;
    denoiser.setInterruptCheck([&] {
        std::unique_lock<std::mutex> lock(mutex);
        inside = true;
        changed.notify_all();
        changed.wait(lock, [&] { return released; });
        return false;
    });
    std::vector<float> first;
    std::thread a([&] { first = denoiser.denoise(frames[0]); });
    {
        std::unique_lock<std::mutex> lock(mutex);
        changed.wait(lock, [&] { return inside; });
    }
    auto expectBusy = [](auto call, const char* name) {
        try {
            call();
            ADD_FAILURE() << name << " ran beside another call";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(std::string(name) + ": the Denoiser is busy"), std::string::npos)
                << e.what();
        }
    };
    expectBusy([&] { denoiser.denoise(frames[0]); }, "denoise");
    expectBusy([&] { denoiser.addSamples(12, 10, 2, frames[0].samples().data()); }, "addSamples");
    expectBusy([&] { denoiser.reset(); }, "reset");
    {
        std::lock_guard<std::mutex> lock(mutex);
        released = true;
    }
    changed.notify_all();
    a.join();
    Denoiser alone(randomModel(3));
    EXPECT_EQ(first, alone.denoise(frames[0]));
    EXPECT_EQ(denoiser.denoise(frames[0]).size(), first.size());  // free again once the call is over
}

// Issue 42, item 11: the interrupt check runs between the steps of a frame; when it says stop,
// the frame is abandoned and the next one starts a new sequence, as after reset().
TEST(Denoiser, AnInterruptAbandonsTheFrameAndTheNextStartsANewSequence) {
    const auto frames = test::randomSequence(3, 12, 10, 2, 7);
    Denoiser reference(randomModel(4));
    int checksPerFrame = 0;
    reference.setInterruptCheck([&] { return ++checksPerFrame, false; });
    reference.denoise(frames[0]);
    // Every U-Net level, convolution and band of the kernels (7 on this small model, 12 rows):
    // a prompt stop, not one check per frame.
    EXPECT_GE(checksPerFrame, 6);
    Denoiser fresh(randomModel(4));
    const std::vector<float> alone = fresh.denoise(frames[2]);

    for (const bool streamed : {false, true}) {
        Denoiser denoiser(randomModel(4));
        denoiser.denoise(frames[0]);
        int calls = 0;
        denoiser.setInterruptCheck([&] { return ++calls == checksPerFrame / 2; });
        if (streamed) {
            denoiser.addSamples(12, 10, 2, frames[1].samples().data());
            EXPECT_THROW(denoiser.finishFrame(frames[1].motion().data(), frames[1].valid().data(), frames[1].info),
                         Interrupted);
        } else {
            EXPECT_THROW(denoiser.denoise(frames[1]), Interrupted);
        }
        EXPECT_EQ(calls, checksPerFrame / 2) << "stopped at once";
        denoiser.setInterruptCheck({});
        DenoiseReport report;
        EXPECT_EQ(denoiser.denoise(frames[2], &report), alone) << "streamed " << streamed;
        EXPECT_FALSE(report.usedHistory);
    }
}

TEST(Denoiser, HistoryIsDroppedWhenTheSizeChangesOrTheCameraJumps) {
    Denoiser denoiser(randomModel());
    auto small = test::randomSequence(2, 8, 6, 1, 1);
    auto large = test::randomSequence(2, 9, 6, 1, 2);
    DenoiseReport report;
    denoiser.denoise(small[0]);
    denoiser.denoise(large[1], &report);
    EXPECT_FALSE(report.usedHistory);
    EXPECT_EQ(report.resetReason, "frame size changed");
    SampleFrame turned = large[1];
    // 90 degrees about Y: the camera now looks along another axis.
    turned.info.worldToCamera = {0, 0, -1, 0, 0, 1, 0, 0, 1, 0, 0, -5, 0, 0, 0, 1};
    denoiser.denoise(turned, &report);
    EXPECT_FALSE(report.usedHistory);
    EXPECT_NE(report.resetReason.find("camera turned"), std::string::npos);
    denoiser.denoise(turned, &report);
    EXPECT_TRUE(report.usedHistory);
    EXPECT_TRUE(report.resetReason.empty());
}

TEST(Denoiser, BuffersThatDoNotMatchTheFrameAreAnErrorNamingTheSize) {
    auto frames = test::randomSequence(1, 6, 5, 2, 12);
    frames[0].motion().pop_back();
    Denoiser denoiser(randomModel());
    try {
        denoiser.denoise(frames[0]);
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("denoise: the frame's buffers do not match its size 6x5 at 2 spp"),
                  std::string::npos)
            << e.what();
    }
    SampleFrameView missing;
    missing.width = 6, missing.height = 5, missing.spp = 2;
    EXPECT_THROW(denoiser.denoise(missing), Error);
}

namespace {

// Samples [first, first + count) of every pixel: the buffer a streaming caller would pass.
std::vector<float> sampleBatch(const SampleFrame& frame, int first, int count) {
    std::vector<float> batch;
    for (int y = 0; y < frame.height(); ++y)
        for (int x = 0; x < frame.width(); ++x)
            for (int s = first; s < first + count; ++s)
                batch.insert(batch.end(), frame.sample(x, y, s), frame.sample(x, y, s) + kFeatureCount);
    return batch;
}

std::vector<float> streamed(Denoiser& denoiser, const SampleFrame& frame, const std::vector<int>& batchSizes,
                            DenoiseReport* report = nullptr) {
    int first = 0;
    for (int count : batchSizes) {
        const std::vector<float> batch = sampleBatch(frame, first, count);
        denoiser.addSamples(frame.width(), frame.height(), count, batch.data());
        first += count;
    }
    EXPECT_EQ(denoiser.pending().spp, frame.spp());
    return denoiser.finishFrame(frame.motion().data(), frame.valid().data(), frame.info, report);
}

}  // namespace

// Every sample of a pixel at sample 0's depth makes the first batch's depth normalisation the
// whole frame's, and then streaming must be the same function bit for bit, whatever the batches.
// Every sample's radiance (diffuse and specular) times `factor`.
std::vector<SampleFrame> scaledRadiance(std::vector<SampleFrame> frames, float factor) {
    for (SampleFrame& f : frames)
        for (int y = 0; y < f.height(); ++y)
            for (int x = 0; x < f.width(); ++x)
                for (int s = 0; s < f.spp(); ++s)
                    for (int c = 0; c < 6; ++c) f.sample(x, y, s)[channel::kDiffuse + c] *= factor;
    return frames;
}

// Outside the brightness range the network was trained on, the exposure normalisation makes the
// denoiser equivariant: a scene 10x brighter still (or dimmer) than one already beyond the range
// gives the output 10x (1/10) up to float rounding, at every frame. Without it the network would
// see log(1 + 10 r) instead of log(1 + r): another input altogether. (The random frames' key is
// about 1, above the range; x 1e-4 takes it below.)
TEST(DenoiserExposure, BeyondTheTrainedRangeScalingTheRadianceScalesTheOutput) {
    const auto frames = test::randomSequence(3, 21, 13, 2, 31);
    for (const auto& [base, factor] : {std::pair{1.0f, 10.0f}, std::pair{1.0f, 100.0f}, std::pair{1e-4f, 0.1f}}) {
        Denoiser plain(randomModel(5)), scaled(randomModel(5));
        const auto first = scaledRadiance(frames, base), second = scaledRadiance(frames, base * factor);
        for (std::size_t t = 0; t < frames.size(); ++t) {
            DenoiseReport plainReport, scaledReport;
            std::vector<float> expected = plain.denoise(first[t], &plainReport);
            for (float& v : expected) v *= factor;
            EXPECT_LT(maxRelativeDifference(scaled.denoise(second[t], &scaledReport), expected), 1e-4)
                << "base " << base << " factor " << factor << " frame " << t;
            EXPECT_NE(plainReport.exposure, 1.0f);
            EXPECT_NEAR(scaledReport.exposure * factor, plainReport.exposure, 1e-5 * plainReport.exposure);
        }
    }
}

TEST(DenoiserExposure, TheFirstFrameOfASequenceSetsIt) {
    auto frames = test::randomSequence(3, 16, 16, 1, 32);
    frames[1] = scaledRadiance({frames[1]}, 10.0f)[0];
    frames[2] = scaledRadiance({frames[0]}, 10.0f)[0];  // frame 0, 10x brighter
    Denoiser denoiser(randomModel(6));
    DenoiseReport first, second, afterReset;
    denoiser.denoise(frames[0], &first);
    denoiser.denoise(frames[1], &second);
    EXPECT_GT(first.exposure, 0.0f);
    EXPECT_EQ(second.exposure, first.exposure);  // kept, although frame 1 is 10x brighter
    denoiser.reset();
    denoiser.denoise(frames[2], &afterReset);
    // A new sequence: frame 0 10x brighter, so a tenth of its exposure.
    EXPECT_NEAR(afterReset.exposure / first.exposure, 0.1f, 1e-6f);
}

TEST(DenoiserExposure, BlackFramesLeaveItToTheFirstFrameWithLight) {
    auto frames = test::randomSequence(2, 16, 16, 1, 33);
    frames[0] = scaledRadiance({frames[0]}, 0.0f)[0];
    Denoiser denoiser(randomModel(7)), fresh(randomModel(7));
    DenoiseReport black, lit, alone;
    EXPECT_TRUE(allFinite(denoiser.denoise(frames[0], &black)));
    denoiser.denoise(frames[1], &lit);
    fresh.denoise(frames[1], &alone);
    EXPECT_EQ(black.exposure, 1.0f);
    EXPECT_EQ(lit.exposure, alone.exposure);
    EXPECT_NE(lit.exposure, 1.0f);
}

// With `precision`, both denoisers' models in it (bfloat16: the same bits too).
void expectBatchesGiveTheWholeFrameResult(Precision precision) {
    auto frames = test::randomSequence(3, 17, 11, 4, 21);
    // The depth scale comes from the first batch of every frame, the exposure from the first
    // batch of the sequence: make those the whole frames' too.
    for (std::size_t t = 0; t < frames.size(); ++t) {
        SampleFrame& f = frames[t];
        for (int y = 0; y < f.height(); ++y)
            for (int x = 0; x < f.width(); ++x)
                for (int s = 1; s < f.spp(); ++s) {
                    f.sample(x, y, s)[channel::kDepth] = f.sample(x, y, 0)[channel::kDepth];
                    if (t == 0)
                        for (int c = 0; c < 6; ++c)
                            f.sample(x, y, s)[channel::kDiffuse + c] = f.sample(x, y, 0)[channel::kDiffuse + c];
                }
    }
    const std::vector<std::vector<int>> batchings = {{1, 1, 2}, {1, 1, 1, 1}, {4}};
    const Weights weights = test::randomWeights(test::ModelShape{}, 3);
    Denoiser whole(Model::fromWeights(weights, precision)), stream(Model::fromWeights(weights, precision));
    for (std::size_t t = 0; t < frames.size(); ++t) {
        DenoiseReport report;
        const std::vector<float> expected = whole.denoise(frames[t]);
        EXPECT_EQ(streamed(stream, frames[t], batchings[t], &report), expected) << "frame " << t;
        EXPECT_EQ(stream.pending().spp, 0);
        EXPECT_EQ(report.usedHistory, t > 0);
        EXPECT_EQ(report.stageMilliseconds.front().first, "embedding");
    }
}

TEST(DenoiserStreaming, BatchesGiveTheWholeFrameResultBitForBit) {
    expectBatchesGiveTheWholeFrameResult(Precision::Float32);
}

TEST(DenoiserBFloat16, BatchesGiveTheWholeFrameResultBitForBit) {
    if (!bfloat16Supported()) GTEST_SKIP() << "no AVX512-BF16 on this CPU";
    expectBatchesGiveTheWholeFrameResult(Precision::BFloat16);
}

TEST(DenoiserStreaming, OnlyTheDepthNormalisationDiffersWhenDepthsVary) {
    auto frames = test::randomSequence(2, 12, 10, 4, 22);
    Denoiser whole(randomModel(4)), stream(randomModel(4));
    for (const SampleFrame& frame : frames) {
        const std::vector<float> expected = whole.denoise(frame);
        const std::vector<float> got = streamed(stream, frame, {1, 1, 1, 1});
        // Depths 2-5 at random: sample 0's mean is within a few percent of all samples' mean.
        EXPECT_LT(maxRelativeDifference(got, expected), 0.05);
        EXPECT_NE(got, expected);
    }
}

TEST(DenoiserStreaming, BadRadianceInALaterBatchIsCounted) {
    auto frames = test::randomSequence(1, 8, 6, 2, 23);
    frames[0].sample(3, 2, 1)[channel::kSpecular + 1] = std::nanf("");
    frames[0].sample(0, 0, 1)[channel::kDiffuse] = -2.0f;
    Denoiser denoiser(randomModel());
    DenoiseReport report;
    const std::vector<float> out = streamed(denoiser, frames[0], {1, 1}, &report);
    EXPECT_TRUE(allFinite(out));
    EXPECT_EQ(report.invalidRadiance, 2);
}

TEST(DenoiserStreaming, MisuseIsAnErrorAndDiscardingStartsOver) {
    auto frames = test::randomSequence(1, 8, 6, 2, 24);
    const SampleFrame& frame = frames[0];
    Denoiser denoiser(randomModel()), fresh(randomModel());
    EXPECT_THROW(denoiser.finishFrame(frame.motion().data(), frame.valid().data(), frame.info), Error);
    const std::vector<float> batch = sampleBatch(frame, 0, 1);
    EXPECT_THROW(denoiser.addSamples(8, 6, 0, batch.data()), Error);
    EXPECT_THROW(denoiser.addSamples(8, 6, 1, nullptr), Error);
    denoiser.addSamples(8, 6, 1, batch.data());
    try {
        denoiser.addSamples(6, 8, 1, batch.data());
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("6x8 batch does not match the frame's first batch of 8x6"),
                  std::string::npos)
            << e.what();
    }
    EXPECT_THROW(denoiser.denoise(frame), Error);  // samples are waiting
    EXPECT_EQ(denoiser.pending().spp, 1);
    EXPECT_EQ(denoiser.pending().width, 8);
    EXPECT_EQ(denoiser.pending().height, 6);
    denoiser.discardSamples();
    EXPECT_EQ(denoiser.pending().spp, 0);
    EXPECT_EQ(denoiser.denoise(frame), fresh.denoise(frame));
}

namespace {

// Fills the bands a denoiser lends with a frame's samples, checking that they cover its rows
// in order.
void fillBands(const std::vector<SampleBand>& bands, const SampleFrame& frame) {
    int row = 0;
    const std::size_t rowValues = std::size_t(frame.width()) * frame.spp() * kFeatureCount;
    for (const SampleBand& band : bands) {
        EXPECT_EQ(band.firstRow, row);
        ASSERT_GT(band.rows, 0);
        std::copy_n(frame.sample(0, band.firstRow, 0), std::size_t(band.rows) * rowValues, band.samples);
        row += band.rows;
    }
    EXPECT_EQ(row, frame.height());
}

std::vector<float> lent(Denoiser& denoiser, const SampleFrame& frame, DenoiseReport* report = nullptr) {
    fillBands(denoiser.sampleBands(frame.width(), frame.height(), frame.spp()), frame);
    EXPECT_EQ(denoiser.pending().spp, frame.spp());
    return denoiser.finishFrame(frame.motion().data(), frame.valid().data(), frame.info, report);
}

}  // namespace

// The test model's embedding has E = 8 channels: a band holds at most 8 floats per pixel of
// the frame, so a 4-spp frame (72 floats per pixel) comes in bands of height / 9 rows and the
// embedding's chunks of 24 pixels straddle bands.
TEST(DenoiserLentBands, BandsGiveTheWholeFrameResultBitForBit) {
    auto frames = test::randomSequence(3, 17, 27, 4, 31);
    frames[1].sample(5, 20, 2)[channel::kDiffuse] = -1.0f;  // counted the same way
    Denoiser whole(randomModel(5)), lending(randomModel(5));
    for (std::size_t t = 0; t < frames.size(); ++t) {
        DenoiseReport expectedReport, report;
        const std::vector<float> expected = whole.denoise(frames[t], &expectedReport);
        EXPECT_EQ(lent(lending, frames[t], &report), expected) << "frame " << t;
        EXPECT_EQ(lending.pending().spp, 0);
        EXPECT_EQ(report.invalidRadiance, expectedReport.invalidRadiance);
        EXPECT_EQ(report.usedHistory, t > 0);
    }
}

TEST(DenoiserLentBands, EachBandHoldsAtMostOneEmbeddingMapOfFloats) {
    Denoiser denoiser(randomModel());
    const int embedding = test::ModelShape{}.embedding.back();
    for (const int spp : {1, 2, 4, 8}) {
        const auto bands = denoiser.sampleBands(16, 90, spp);
        const int bandRows = std::max(1, 90 * embedding / (spp * kFeatureCount));
        EXPECT_EQ(bands.size(), std::size_t((90 + bandRows - 1) / bandRows)) << spp << " spp";
        for (const auto& band : bands)
            EXPECT_LE(std::size_t(band.rows) * 16 * spp * kFeatureCount,
                      std::max<std::size_t>(std::size_t(90) * 16 * embedding, std::size_t(16) * spp * kFeatureCount));
        denoiser.discardSamples();
    }
    EXPECT_EQ(denoiser.sampleBands(5, 3, 8).size(), 3u);  // a band holds at least one row
}

TEST(DenoiserLentBands, MisuseIsAnErrorAndDiscardingStartsOver) {
    auto frames = test::randomSequence(1, 8, 6, 2, 32);
    const SampleFrame& frame = frames[0];
    Denoiser denoiser(randomModel()), fresh(randomModel());
    EXPECT_THROW(denoiser.sampleBands(0, 6, 2), Error);
    EXPECT_THROW(denoiser.sampleBands(8, 6, SampleFrame::kMaxSpp + 1), Error);
    fillBands(denoiser.sampleBands(8, 6, 2), frame);
    EXPECT_THROW(denoiser.sampleBands(8, 6, 2), Error);  // the lent frame waits
    const std::vector<float> batch(std::size_t(8) * 6 * kFeatureCount, 0.5f);
    try {
        denoiser.addSamples(8, 6, 1, batch.data());
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("sampleBands"), std::string::npos) << e.what();
    }
    EXPECT_THROW(denoiser.denoise(frame), Error);
    EXPECT_EQ(denoiser.pending().width, 8);
    EXPECT_EQ(denoiser.pending().height, 6);
    denoiser.discardSamples();
    EXPECT_EQ(denoiser.pending().spp, 0);
    EXPECT_THROW(denoiser.finishFrame(frame.motion().data(), frame.valid().data(), frame.info), Error);
    // Streaming samples wait: no bands.
    denoiser.addSamples(8, 6, 1, batch.data());
    EXPECT_THROW(denoiser.sampleBands(8, 6, 2), Error);
    denoiser.discardSamples();
    EXPECT_EQ(lent(denoiser, frame), fresh.denoise(frame));
    // A finishFrame() refused for a missing buffer leaves the lent frame waiting.
    Denoiser again(randomModel()), reference(randomModel());
    fillBands(again.sampleBands(8, 6, 2), frame);
    EXPECT_THROW(again.finishFrame(nullptr, frame.valid().data(), frame.info), Error);
    EXPECT_EQ(again.pending().spp, 2);
    EXPECT_EQ(again.finishFrame(frame.motion().data(), frame.valid().data(), frame.info), reference.denoise(frame));
}

// What lending buys, in the denoiser's own accounting (deterministic, unlike the process's
// memory): the lent input's memory is taken over by later maps, so the denoiser's buffers grow
// by much less than the input it no longer needs the caller to hold, and stop growing (with the
// built-in model, by under half the input, here as at 1080p).
TEST(DenoiserLentBands, TheBandsMemoryServesTheLaterMaps) {
    auto frames = test::randomSequence(4, 160, 120, 4, 33);
    Denoiser whole(Model::builtIn(Precision::Float32)), lending(Model::builtIn(Precision::Float32));
    std::vector<std::size_t> wholeBytes, lentBytes;
    for (const SampleFrame& frame : frames) {
        DenoiseReport report;
        (void)whole.denoise(frame, &report);
        wholeBytes.push_back(report.bufferBytes);
        (void)lent(lending, frame, &report);
        lentBytes.push_back(report.bufferBytes);
    }
    const std::size_t input = frames[0].samples().size() * sizeof(float);
    EXPECT_EQ(wholeBytes[3], wholeBytes[2]);
    EXPECT_EQ(lentBytes[3], lentBytes[2]);
    EXPECT_GT(wholeBytes[3], input);  // the maps are more memory than the input: room to reuse it
    EXPECT_LT(double(lentBytes[3]), double(wholeBytes[3]) + 0.6 * double(input))
        << "whole " << wholeBytes[3] << " lent " << lentBytes[3] << " input " << input;
}

TEST(DenoiserExposure, ACameraCutStartsANewSequence) {
    auto frames = test::randomSequence(2, 16, 16, 1, 34);
    frames[1] = scaledRadiance({frames[0]}, 10.0f)[0];
    frames[1].info.worldToCamera = {0, 0, -1, 0, 0, 1, 0, 0, 1, 0, 0, -5, 0, 0, 0, 1};  // turned 90 degrees
    for (const bool streamedFrames : {false, true}) {
        Denoiser denoiser(randomModel(8));
        DenoiseReport first, cut;
        denoiser.denoise(frames[0], &first);
        if (streamedFrames)  // the cut shows only at finishFrame(): the frame keeps the exposure
            streamed(denoiser, frames[1], {1}, &cut);
        else
            denoiser.denoise(frames[1], &cut);
        EXPECT_FALSE(cut.resetReason.empty());
        EXPECT_NEAR(cut.exposure / first.exposure, streamedFrames ? 1.0f : 0.1f, 1e-6f) << streamedFrames;
    }
}

// The light restoration (docs/MODEL.md section 10) runs where the weights file asks for it:
// without the switch the output is the kernels' own, bit for bit.
TEST(Denoiser, TheWeightsFileSwitchesTheLightRestoration) {
    auto frames = test::randomSequence(2, 12, 10, 2, 12);
    auto modelWith = [](int value) {
        auto tensors = test::randomModelTensors(test::ModelShape{}, 5);
        if (value >= 0) tensors.push_back({"config.light_restoration", DType::Int32, {1}, {}, {value}});
        const auto bytes = train::serializeWeights(tensors);
        return Model::fromWeights(Weights::fromMemory(bytes.data(), bytes.size(), "model"), Precision::Float32);
    };
    const Model absent = modelWith(-1), off = modelWith(0), on = modelWith(1);
    EXPECT_FALSE(absent.lightRestoration());
    EXPECT_FALSE(off.lightRestoration());
    EXPECT_TRUE(on.lightRestoration());
    EXPECT_FALSE(Model::builtIn().lightRestoration());
    EXPECT_THROW(modelWith(2), Error);
    const Ablation noFallback{.inputFallback = false, .peakGuard = false};
    Denoiser plain = ablatedDenoiser(absent, noFallback), restoring = ablatedDenoiser(on, noFallback);
    Denoiser kernelsOnly = ablatedDenoiser(on, {.lightRestoration = false, .inputFallback = false, .peakGuard = false});
    for (const auto& frame : frames) {
        const std::vector<float> kernels = kernelsOnly.denoise(frame);
        EXPECT_EQ(plain.denoise(frame), kernels);
        DenoiseReport report;
        EXPECT_NE(restoring.denoise(frame, &report), kernels);
        ASSERT_EQ(report.stageMilliseconds.size(), 7u);
        EXPECT_EQ(report.stageMilliseconds.back().first, "light restoration");
    }
}
