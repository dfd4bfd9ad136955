// Same function in two places: the C++ inference pipeline against the libtorch training
// model on the same weights and the same multi-frame sequences (docs/MODEL.md).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>

#include <gtest/gtest.h>
#include <torch/torch.h>

#include "affinity/denoiser.h"
#include "affinity/error.h"
#include "affinity/weights.h"
#include "affinity_ops.h"
#include "kernels/catmull_rom_warp.h"
#include "model_config.h"
#include "network/network.h"
#include "model_surgery.h"
#include "model_weights.h"
#include "network_denoiser.h"
#include "random_model.h"
#include "torch_reference.h"

using namespace affinity;

namespace {

// max |a - b| / (|b| + 1e-3): relative, with a floor for near-black pixels.
double maxRelativeDifference(const std::vector<float>& a, const std::vector<float>& b) {
    double worst = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i)
        worst = std::max(worst, std::abs(double(a[i]) - b[i]) / (std::abs(double(b[i])) + 1e-3));
    return worst;
}

void expectParity(const std::string& weightsPath, const std::vector<SampleFrame>& frames) {
    const std::vector<std::vector<float>> expected = train::torchDenoiseSequence(weightsPath, frames);
    Denoiser denoiser = test::networkDenoiser(weightsPath);  // in FP32, as libtorch computes
    ASSERT_EQ(expected.size(), frames.size());
    for (std::size_t t = 0; t < frames.size(); ++t) {
        std::vector<float> actual = denoiser.denoise(frames[t]);
        ASSERT_EQ(actual.size(), expected[t].size());
        EXPECT_LT(maxRelativeDifference(actual, expected[t]), 1e-4) << weightsPath << " frame " << t;
    }
}

std::string temporaryPath(const std::string& name) {
    return (std::filesystem::temp_directory_path() / ("affinity_parity_" + name)).string();
}

}  // namespace

TEST(Parity, CatmullRomWarpOfTheCoreAndTheTrainingFramework) {
    // The sharp radiance warp alone, on motions that reach past the border and land on whole
    // pixels, so both the clamps and the tap arithmetic are compared.
    torch::manual_seed(5);
    const int height = 17, width = 23;
    const torch::Tensor previous = torch::randn({1, 3, height, width}) * 2;
    torch::Tensor motion = (torch::rand({1, 2, height, width}) - 0.5) * 12;
    motion.narrow(2, 0, 3).round_();
    const torch::Tensor expected = train::warpCatmullRom(previous, motion).squeeze(0).permute({1, 2, 0}).contiguous();
    FeatureMap map(height, width, 3), warped;
    const torch::Tensor hwc = previous.squeeze(0).permute({1, 2, 0}).contiguous();
    std::copy(hwc.data_ptr<float>(), hwc.data_ptr<float>() + hwc.numel(), map.data());
    const torch::Tensor motionHw2 = motion.squeeze(0).permute({1, 2, 0}).contiguous();
    warpCatmullRom(map, motionHw2.data_ptr<float>(), warped);
    double worst = 0.0;
    for (std::int64_t i = 0; i < expected.numel(); ++i)
        worst = std::max(worst, double(std::abs(warped.data()[i] - expected.data_ptr<float>()[i])));
    EXPECT_LT(worst, 1e-5);
}

TEST(Parity, RandomWeightsOnRandomSequences) {
    for (unsigned seed : {1u, 2u}) {
        const std::string path = temporaryPath("random" + std::to_string(seed) + ".affw");
        train::writeWeightsFile(path, test::randomModelTensors(test::ModelShape{}, seed));
        expectParity(path, test::randomSequence(4, 23, 17, 3, seed));
        std::filesystem::remove(path);
    }
}

// Frames taller than the kernel stage's bands (128 rows each, rings of 158 rows):
// parameters, accumulation and kernels run band by band on the C++ side, whole on the other.
TEST(Parity, FramesOfSeveralBands) {
    const std::string path = temporaryPath("tall.affw");
    train::writeWeightsFile(path, test::randomModelTensors(test::ModelShape{}, 8));
    expectParity(path, test::randomSequence(3, 6, 231, 2, 8));
    std::filesystem::remove(path);
}

TEST(Parity, DarkAlbedoAndNonFiniteFeatures) {
    for (unsigned seed : {3u, 9u}) {
        const std::string path = temporaryPath("nonfinite" + std::to_string(seed) + ".affw");
        train::writeWeightsFile(path, test::randomModelTensors(test::ModelShape{}, seed));
        std::vector<SampleFrame> frames = test::randomSequence(4, 23, 17, 3, seed);
        // Black and dark albedo, and non-finite features, which both sides read as 0.
        for (SampleFrame& frame : frames) {
            for (int s = 0; s < frame.spp(); ++s) {
                frame.sample(0, 0, s)[channel::kAlbedo] = 0.0f;
                frame.sample(1, 0, s)[channel::kAlbedo + 1] = 0.002f;
            }
            frame.sample(2, 0, 0)[channel::kAlbedo + 2] = INFINITY;
            frame.sample(3, 0, 1)[channel::kNormal] = std::nanf("");
            frame.sample(4, 0, 2)[channel::kRoughness] = -INFINITY;
        }
        expectParity(path, frames);
        std::filesystem::remove(path);
    }
}

// The shipped default grown to the medium preset's widths computes what it did (up to the
// convolutions' summation order, which the wider layers change), and both sides still agree.
TEST(Parity, WideningATrainedModelKeepsTheFunction) {
    const std::string original = std::string(AFFINITY_SOURCE_DIR) + "/core/models/default.affw";
    const std::string fresh = temporaryPath("medium_fresh.affw"), wide = temporaryPath("medium_widened.affw");
    const Weights trained = Weights::fromFile(original);
    train::writeInitialModel(train::presetConfig("medium"), 3, fresh);
    train::writeWeightsFile(wide, train::widened(trained, Weights::fromFile(fresh)));
    const Weights grown = Weights::fromFile(wide);
    EXPECT_GT(grown.tensor("unet.dec0.conv0.weight").count, trained.tensor("unet.dec0.conv0.weight").count);
    const std::vector<SampleFrame> frames = test::randomSequence(3, 37, 29, 4, 21);
    Denoiser before(Model::fromFile(original, Precision::Float32)), after(Model::fromFile(wide, Precision::Float32));
    for (std::size_t t = 0; t < frames.size(); ++t)
        EXPECT_LT(maxRelativeDifference(after.denoise(frames[t]), before.denoise(frames[t])), 1e-5) << "frame " << t;
    expectParity(wide, frames);
    // A model cannot be widened into a narrower or differently shaped one.
    const std::string tiny = temporaryPath("tiny_fresh.affw");
    train::writeInitialModel(train::presetConfig("tiny"), 3, tiny);
    EXPECT_THROW(train::widened(trained, Weights::fromFile(tiny)), Error);
    EXPECT_THROW(train::widened(grown, Weights::fromFile(original)), Error);
    for (const std::string& path : {fresh, wide, tiny}) std::filesystem::remove(path);
}

// The shipped default with a fourth, wider kernel: both sides agree on it; on a first frame (no
// temporal taps) with the new kernel's bandwidth scaled far up, its neighbours weigh nothing and
// the output is the three-kernel model's.
TEST(Parity, AddingAKernelToATrainedModel) {
    const std::string original = std::string(AFFINITY_SOURCE_DIR) + "/core/models/default.affw";
    const std::string grown = temporaryPath("default_k4.affw"), strict = temporaryPath("default_k4_strict.affw");
    const Weights trained = Weights::fromFile(original);
    train::writeWeightsFile(grown, train::withKernelAdded(trained, 2.0));
    train::writeWeightsFile(strict, train::withKernelAdded(trained, 1e4));
    EXPECT_EQ(train::configFromWeights(Weights::fromFile(grown)).kernels, 4);
    EXPECT_EQ(Weights::fromFile(grown).tensor("unet.head.bias").count, 42u);  // 4 x (8 + 2) + 2
    const std::vector<SampleFrame> frames = test::randomSequence(3, 41, 35, 4, 23);
    expectParity(grown, frames);

    Denoiser before(Model::fromFile(original, Precision::Float32)), after(Model::fromFile(strict, Precision::Float32));
    const std::vector<float> threeKernels = before.denoise(frames[0]), fourKernels = after.denoise(frames[0]);
    EXPECT_LT(maxRelativeDifference(fourKernels, threeKernels), 1e-3);
    Denoiser loose(Model::fromFile(grown, Precision::Float32));
    EXPECT_GT(maxRelativeDifference(loose.denoise(frames[0]), threeKernels), 1e-2);  // the wide pass filters

    EXPECT_THROW(train::withKernelAdded(trained, 0.0), Error);
    EXPECT_THROW(train::withKernelAdded(trained, -1.0), Error);
    for (const std::string& path : {grown, strict}) std::filesystem::remove(path);
}

TEST(Parity, EveryPresetAtInitialisation) {
    for (const std::string& preset : train::presetNames()) {
        const std::string path = temporaryPath(preset + ".affw");
        train::writeInitialModel(train::presetConfig(preset), 7, path);
        expectParity(path, test::randomSequence(3, 19, 13, 2, 11));
        std::filesystem::remove(path);
    }
}

TEST(Parity, TheShippedDefaultModel) {
    expectParity(std::string(AFFINITY_SOURCE_DIR) + "/core/models/default.affw", test::randomSequence(3, 16, 16, 4, 5));
}

// A temporal gain (docs/MODEL.md section 7) is part of the network: the trainer and the core
// compute the same with it, it changes what the history gives, and a training exports it again.
TEST(Parity, ATemporalGain) {
    const std::string original = std::string(AFFINITY_SOURCE_DIR) + "/core/models/default.affw";
    const std::string gained = temporaryPath("default_gain250.affw");
    const Weights trained = Weights::fromFile(original);
    train::writeWeightsFile(gained, train::withTemporalGain(trained, 250));
    EXPECT_EQ(train::configFromWeights(Weights::fromFile(gained)).temporalGainPercent, 250);
    const std::vector<SampleFrame> frames = test::randomSequence(3, 29, 23, 4, 31);
    expectParity(gained, frames);

    Denoiser plain(Model::fromFile(original, Precision::Float32)), more(Model::fromFile(gained, Precision::Float32));
    std::vector<float> a, b;
    for (const SampleFrame& frame : frames) a = plain.denoise(frame), b = more.denoise(frame);
    EXPECT_GT(maxRelativeDifference(b, a), 1e-3);  // the last frame leans more on its history

    const std::vector<std::uint8_t> exported =
        train::serializeWeights(train::modelTensors(train::modelFromWeights(Weights::fromFile(gained))));
    EXPECT_EQ(Weights::fromMemory(exported.data(), exported.size(), "exported").integer("config.temporal_gain_percent"),
              250);
    // 100 is the file as trained: the tensor left out.
    const auto back = train::serializeWeights(train::withTemporalGain(Weights::fromFile(gained), 100));
    EXPECT_FALSE(Weights::fromMemory(back.data(), back.size(), "back").has("config.temporal_gain_percent"));
    EXPECT_THROW(train::withTemporalGain(trained, 0), Error);
    EXPECT_THROW(train::withTemporalGain(trained, kMaxTemporalGainPercent + 1), Error);
    // The core refuses a gain out of range, naming it.
    std::vector<train::NamedTensor> zero = train::withTemporalGain(trained, 250);
    for (train::NamedTensor& tensor : zero)
        if (tensor.name == "config.temporal_gain_percent") tensor.ints = {0};
    const auto zeroBytes = train::serializeWeights(zero);
    try {
        Model::fromWeights(Weights::fromMemory(zeroBytes.data(), zeroBytes.size(), "zero gain"));
        ADD_FAILURE() << "a temporal gain of 0 % was accepted";
    } catch (const Error& error) {
        EXPECT_NE(std::string(error.what()).find("config.temporal_gain_percent"), std::string::npos) << error.what();
    }
    std::filesystem::remove(gained);
}

// The light restoration's switch (docs/MODEL.md section 10) changes no tensor of the network,
// and a model trained from a file that has it exports it again.
TEST(ModelSurgery, TheLightRestorationSwitchKeepsTheNetworkAndSurvivesTraining) {
    const Weights trained = Weights::fromFile(std::string(AFFINITY_SOURCE_DIR) + "/core/models/default.affw");
    auto load = [](const std::vector<train::NamedTensor>& tensors, const char* name) {
        const auto bytes = train::serializeWeights(tensors);
        return Weights::fromMemory(bytes.data(), bytes.size(), name);
    };
    const Weights on = load(train::withLightRestoration(trained, true), "on");
    EXPECT_TRUE(Model::fromWeights(on).lightRestoration());
    EXPECT_FALSE(Model::fromWeights(trained).lightRestoration());
    std::vector<std::string> names = on.names();
    names.erase(std::find(names.begin(), names.end(), "config.light_restoration"));
    ASSERT_EQ(names, trained.names());
    for (const std::string& name : names) {
        const TensorView &a = on.tensor(name), &b = trained.tensor(name);
        ASSERT_EQ(a.count, b.count) << name;
        EXPECT_EQ(std::memcmp(a.data, b.data, a.count * 4), 0) << name;  // 4-byte elements
    }
    const Weights exported = load(train::modelTensors(train::modelFromWeights(on)), "exported");
    EXPECT_TRUE(Model::fromWeights(exported).lightRestoration());
    EXPECT_FALSE(Model::fromWeights(load(train::withLightRestoration(on, false), "off")).lightRestoration());
}
