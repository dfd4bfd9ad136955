// The training side (docs/TRAINING.md): the loss against finite differences and the core's
// metric, and a smoke training of a tiny model on a tiny fixed dataset that must lower the
// validation loss, export, load in the core and match the torch model.
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <ostream>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <torch/torch.h>

#include "affinity/denoiser.h"
#include "affinity/error.h"
#include "affinity/frame_io.h"
#include "affinity/metrics.h"
#include "affinity_ops.h"
#include "network_denoiser.h"
#include "torch_reference.h"
#include "train_augment.h"
#include "train_loss.h"
#include "trainer.h"

using namespace affinity;
namespace fs = std::filesystem;

namespace {

// Every term switched on, with weights unlike the defaults, so the gradient check covers them all.
// Coarse cells of 2 pixels on 4 x 3 images: the right column is a partial cell.
const train::LossWeights kAllTerms{0.5, 0.3, true, 0.7, 2, 1.5, 0.4};

double lossValue(const std::vector<torch::Tensor>& outputs, const std::vector<torch::Tensor>& references,
                 const std::vector<std::vector<torch::Tensor>>& bandwidths,
                 const std::vector<train::FrameMotion>& motions, const train::LossWeights& weights) {
    return train::sequenceLoss(outputs, references, bandwidths, weights, motions).total.item<double>();
}

// Two frames of a batch of two 2 x 2 crops for the absolute temporal tests. Crop 0: the output
// steps by 1 where the reference steps by 0.5, on a reference of mean 1.5. Crop 1: a lamp of 100
// flickers by 20 in one of four pixels (all channels); elsewhere 0, everything still.
struct FlickerCrops {
    torch::Tensor o0 = torch::zeros({2, 3, 2, 2}), o1 = torch::zeros({2, 3, 2, 2});
    torch::Tensor r0 = torch::zeros({2, 3, 2, 2}), r1 = torch::zeros({2, 3, 2, 2});
    FlickerCrops() {
        o0[0].fill_(1.0), o1[0].fill_(2.0), r0[0].fill_(1.0), r1[0].fill_(1.5);
        o0[1].select(1, 0).select(1, 0).fill_(100.0), o1[1].select(1, 0).select(1, 0).fill_(120.0);
        r0[1].select(1, 0).select(1, 0).fill_(100.0), r1[1].select(1, 0).select(1, 0).fill_(100.0);
    }
    train::LossTerms loss(const train::LossWeights& weights) const {
        return train::sequenceLoss({o0, o1}, {r0, r1}, {}, weights);
    }
};

}  // namespace

TEST(TrainingLoss, SmapeMatchesTheCoreMetric) {
    torch::manual_seed(3);
    const torch::Tensor image = torch::rand({1, 3, 7, 5}) * 4, reference = torch::rand({1, 3, 7, 5}) * 4;
    const torch::Tensor a = image.permute({0, 2, 3, 1}).contiguous(), b = reference.permute({0, 2, 3, 1}).contiguous();
    EXPECT_NEAR(train::smapeLoss(image, reference).item<double>(),
                smape(a.data_ptr<float>(), b.data_ptr<float>(), std::size_t(a.numel())), 1e-6);
}

TEST(TrainingLoss, TermsFollowTheDefinition) {
    // Two frames, constant images: every term by hand.
    const torch::Tensor o0 = torch::full({1, 3, 2, 2}, 1.0), o1 = torch::full({1, 3, 2, 2}, 2.0);
    const torch::Tensor r0 = torch::full({1, 3, 2, 2}, 1.5), r1 = torch::full({1, 3, 2, 2}, 2.0);
    const torch::Tensor a = torch::full({1, 1, 2, 2}, 3.0), b = torch::full({1, 1, 2, 2}, 2.0);
    const train::LossTerms terms = train::sequenceLoss({o0, o1}, {r0, r1}, {{a, b}, {a, b}});
    const double spatial = (0.5 / 2.51 + 0.0) / 2, temporal = 0.5 / (1.0 + 0.5 + 0.01);
    EXPECT_NEAR(terms.spatial.item<double>(), spatial, 1e-6);
    EXPECT_NEAR(terms.temporal.item<double>(), temporal, 1e-6);
    EXPECT_NEAR(terms.regulariser.item<double>(), 9.0 + 4.0, 1e-5);
    EXPECT_NEAR(terms.total.item<double>(), spatial + 0.25 * temporal + 1e-5 * 13.0, 1e-6);
    EXPECT_EQ(terms.absoluteTemporal.item<double>(), 0.0);  // off in the paper's loss
    EXPECT_EQ(terms.coarse.item<double>(), 0.0);
}

TEST(TrainingLoss, TheFirstFrameWeighsTheImageTermsOfTheTotalOnly) {
    // Frame 0 errs (SMAPE 0.5 / 2.51), frame 1 is exact; with weight 3 on frame 0 its image terms
    // count 3 / (3 + 1) of the total's, while the reported spatial term stays the plain mean.
    const torch::Tensor o0 = torch::full({1, 3, 2, 2}, 1.0), o1 = torch::full({1, 3, 2, 2}, 2.0);
    const torch::Tensor r0 = torch::full({1, 3, 2, 2}, 1.5), r1 = torch::full({1, 3, 2, 2}, 2.0);
    train::LossWeights weights;
    weights.temporal = 0;
    weights.coarse = 1;
    weights.firstFrame = 3;
    const train::LossTerms terms = train::sequenceLoss({o0, o1}, {r0, r1}, {}, weights);
    const double first = 0.5 / 2.51;  // constant images: a cell's mean is the pixel value
    EXPECT_NEAR(terms.spatial.item<double>(), first / 2, 1e-6);
    EXPECT_NEAR(terms.coarse.item<double>(), first / 2, 1e-6);
    EXPECT_NEAR(terms.total.item<double>(), 2 * (3 * first / 4), 1e-6);
    weights.firstFrame = 1;  // the plain means again
    EXPECT_NEAR(train::sequenceLoss({o0, o1}, {r0, r1}, {}, weights).total.item<double>(), 2 * (first / 2), 1e-6);
}

TEST(TrainingLoss, DisplayedTermIsTheErrorOfTheToneMappedGammaEncodedImage) {
    // D(x) = (x / (1 + x) + 0.001)^(1/2.2) - 0.001^(1/2.2): D(1) = 0.687115, D(1.5) = 0.750105.
    train::LossWeights weights;
    weights.displayed = 2;
    const torch::Tensor lit = torch::full({1, 3, 2, 2}, 1.0), litReference = torch::full({1, 3, 2, 2}, 1.5);
    const train::LossTerms terms = train::sequenceLoss({lit}, {litReference}, {}, weights);
    EXPECT_NEAR(terms.displayed.item<double>(), 0.062990, 1e-5);
    EXPECT_NEAR(terms.total.item<double>(), terms.spatial.item<double>() + 2 * 0.062990, 1e-5);
    // The same relative error 100 times darker counts a third: D(0.01) = 0.084927, D(0.015) = 0.108395.
    const train::LossTerms dark = train::sequenceLoss({lit / 100}, {litReference / 100}, {}, weights);
    EXPECT_NEAR(dark.displayed.item<double>(), 0.023468, 1e-5);
    // Below black is black: a negative output errs as much as 0.
    EXPECT_NEAR(train::displayedImage(torch::full({1}, -2.0)).item<double>(), 0.0, 1e-9);
    EXPECT_EQ(train::sequenceLoss({lit}, {litReference}, {}, {}).displayed.item<double>(), 0.0);  // off by default
}

TEST(TrainingLoss, CellMeansAverageBlocksAndPartialBlocksOverTheirPixels) {
    // 3 x 5 image, cells of 2: blocks rows {0,1},{2} x columns {0,1},{2,3},{4}.
    const torch::Tensor image = torch::arange(15, torch::kDouble).view({1, 1, 3, 5});
    const torch::Tensor means = train::cellMeans(image, 2);
    ASSERT_EQ(means.sizes(), (std::vector<std::int64_t>{1, 1, 2, 3}));
    const double expected[2][3] = {{(0 + 1 + 5 + 6) / 4.0, (2 + 3 + 7 + 8) / 4.0, (4 + 9) / 2.0},
                                   {(10 + 11) / 2.0, (12 + 13) / 2.0, 14.0}};
    for (int y = 0; y < 2; ++y)
        for (int x = 0; x < 3; ++x) EXPECT_NEAR(means[0][0][y][x].item<double>(), expected[y][x], 1e-12) << y << x;
    EXPECT_THROW(train::cellMeans(image, 0), Error);
}

TEST(TrainingLoss, CoarseTermSeesLostEnergyButNotEnergyMovedWithinACell) {
    // Reference: a 4 x 4 crop of 1. Output A keeps the energy but puts it in one pixel per 2 x 2
    // cell (4, 0, 0, 0): bad per pixel, perfect per cell. Output B drops a firefly's share and is
    // uniformly 0.8: the coarse term sees the 20% loss in every cell.
    const torch::Tensor reference = torch::ones({1, 3, 4, 4});
    torch::Tensor concentrated = torch::zeros({1, 3, 4, 4});
    concentrated.slice(2, 0, 4, 2).slice(3, 0, 4, 2).fill_(4.0);
    const train::LossWeights coarseOnly{0.25, 0, false, 1.5, 2};
    const train::LossTerms a = train::sequenceLoss({concentrated}, {reference}, {}, coarseOnly);
    EXPECT_NEAR(a.coarse.item<double>(), 0.0, 1e-6);
    EXPECT_NEAR(a.spatial.item<double>(), (3.0 / 5.01 + 3 * (1.0 / 1.01)) / 4, 1e-6);
    const train::LossTerms b = train::sequenceLoss({torch::full({1, 3, 4, 4}, 0.8)}, {reference}, {}, coarseOnly);
    EXPECT_NEAR(b.coarse.item<double>(), 0.2 / 1.81, 1e-6);
    EXPECT_NEAR(b.total.item<double>(), b.spatial.item<double>() + 1.5 * b.coarse.item<double>(), 1e-6);
}

TEST(TrainingLoss, AbsoluteTemporalTermWeighsFlickerBySizePerCropBrightness) {
    const train::LossTerms terms = FlickerCrops().loss({0.25, 2.0});
    const double crop0 = 0.5 / (1.5 + 0.01), crop1 = (20.0 / 4) / (100.0 / 4 + 0.01);
    EXPECT_NEAR(terms.absoluteTemporal.item<double>(), (crop0 + crop1) / 2, 1e-6);
    // The relative (SMAPE) term sees the lamp's flicker as no bigger than a shadow's.
    const double smapeCrop1 = (20.0 / (20.0 + 0.0 + 0.01)) / 4;
    EXPECT_NEAR(terms.temporal.item<double>(), (0.5 / (1.0 + 0.5 + 0.01) + smapeCrop1) / 2, 1e-6);
    EXPECT_NEAR(terms.total.item<double>(),
                terms.spatial.item<double>() + 0.25 * terms.temporal.item<double>() +
                    2.0 * terms.absoluteTemporal.item<double>(),
                1e-6);
}

TEST(TrainingLoss, WarpedTemporalTermsWithoutMotionEqualThePlainOnes) {
    torch::manual_seed(4);
    std::vector<torch::Tensor> outputs, references;
    std::vector<train::FrameMotion> motions;
    for (int t = 0; t < 3; ++t) {
        outputs.push_back(torch::rand({2, 3, 5, 4}) * 3);
        references.push_back(torch::rand({2, 3, 5, 4}) * 3);
        motions.push_back({torch::zeros({2, 2, 5, 4}), torch::ones({2, 1, 5, 4})});
    }
    const train::LossTerms plain = train::sequenceLoss(outputs, references, {}, {0.25, 1.0, false});
    const train::LossTerms warped = train::sequenceLoss(outputs, references, {}, {0.25, 1.0, true}, motions);
    EXPECT_NEAR(warped.temporal.item<double>(), plain.temporal.item<double>(), 1e-6);
    EXPECT_NEAR(warped.absoluteTemporal.item<double>(), plain.absoluteTemporal.item<double>(), 1e-6);
    EXPECT_GT(plain.temporal.item<double>(), 0.1);
    EXPECT_THROW(train::sequenceLoss(outputs, references, {}, {0.25, 1.0, true}), Error);  // no motions
}

TEST(TrainingLoss, WarpedTemporalTermsIgnoreMotionAndCountOnlyPixelsWithHistory) {
    // The image moves one pixel right between the frames; the output is twice the reference
    // (a bias that does not change). Unwarped, dt O = 2 dt O*: flicker where there is none.
    // Warped by the motion, both changes are 0 wherever the warp stays inside the crop.
    torch::manual_seed(6);
    const torch::Tensor r0 = torch::rand({1, 3, 4, 6}) + 0.5;
    torch::Tensor r1 = torch::roll(r0, {1}, {3});
    r1.select(3, 0).fill_(7.0);  // the new column: no history (its warp target x = -1 is outside)
    const torch::Tensor motion = torch::cat({torch::full({1, 1, 4, 6}, -1.0), torch::zeros({1, 1, 4, 6})}, 1);
    const std::vector<torch::Tensor> outputs{2 * r0, 2 * r1}, references{r0, r1};
    const std::vector<train::FrameMotion> motions{{motion, torch::ones({1, 1, 4, 6})},
                                                  {motion, torch::ones({1, 1, 4, 6})}};
    const train::LossTerms plain = train::sequenceLoss(outputs, references, {}, {0.25, 1.0, false});
    const train::LossTerms warped = train::sequenceLoss(outputs, references, {}, {0.25, 1.0, true}, motions);
    EXPECT_GT(plain.temporal.item<double>(), 0.1);
    EXPECT_GT(plain.absoluteTemporal.item<double>(), 0.1);
    EXPECT_NEAR(warped.temporal.item<double>(), 0.0, 1e-6);
    EXPECT_NEAR(warped.absoluteTemporal.item<double>(), 0.0, 1e-6);

    // Flicker of +1 at one counted pixel (x = 3): temporal SMAPE over the 4 x 5 counted pixels x
    // 3 channels is 1 / (1 + 0 + 0.01) per channel there; a flicker in the uncounted column 0, or
    // where the history is invalid, changes nothing.
    torch::Tensor flickering = (2 * r1).clone();
    flickering.select(3, 3).select(2, 1) += 1.0;
    flickering.select(3, 0) += 5.0;
    torch::Tensor valid = torch::ones({1, 1, 4, 6});
    valid.select(3, 5).select(2, 2).fill_(0.0);
    flickering.select(3, 5).select(2, 2) += 9.0;
    const std::vector<train::FrameMotion> withInvalid{{motion, valid}, {motion, valid}};
    const train::LossTerms one =
        train::sequenceLoss({2 * r0, flickering}, references, {}, {0.25, 1.0, true}, withInvalid);
    EXPECT_NEAR(one.temporal.item<double>(), 3 * (1.0 / 1.01) / (3 * 19.0), 1e-5);
}

TEST(TrainingLossGradient, MatchesFiniteDifferences) {
    const train::LossWeights& weights = kAllTerms;
    torch::manual_seed(5);
    const auto options = torch::TensorOptions().dtype(torch::kDouble);
    std::vector<torch::Tensor> outputs, references;
    std::vector<std::vector<torch::Tensor>> bandwidths;
    std::vector<train::FrameMotion> motions;
    for (int t = 0; t < 3; ++t) {
        motions.push_back({torch::rand({2, 2, 4, 3}, options) * 3 - 1.5,
                           (torch::rand({2, 1, 4, 3}, options) > 0.2).to(torch::kDouble)});
        outputs.push_back((torch::rand({2, 3, 4, 3}, options) * 2 - 0.3).requires_grad_(true));
        references.push_back(torch::rand({2, 3, 4, 3}, options) * 2);
        bandwidths.push_back({(torch::randn({2, 1, 4, 3}, options) * 30).requires_grad_(true),
                              (torch::randn({2, 1, 4, 3}, options) * 30).requires_grad_(true)});
    }
    train::sequenceLoss(outputs, references, bandwidths, weights, motions).total.backward();
    const double step = 1e-6;
    auto check = [&](torch::Tensor& tensor) {
        const torch::Tensor gradient = tensor.grad().clone();
        torch::NoGradGuard noGrad;
        auto flat = tensor.view({-1});
        for (std::int64_t i = 0; i < flat.numel(); i += 5) {
            const double saved = flat[i].item<double>();
            flat[i].fill_(saved + step);
            const double plus = lossValue(outputs, references, bandwidths, motions, weights);
            flat[i].fill_(saved - step);
            const double minus = lossValue(outputs, references, bandwidths, motions, weights);
            flat[i].fill_(saved);
            const double numeric = (plus - minus) / (2 * step);
            EXPECT_NEAR(gradient.view({-1})[i].item<double>(), numeric, 1e-6 + 1e-4 * std::abs(numeric)) << i;
        }
    };
    for (auto& tensor : outputs) check(tensor);
    for (auto& frame : bandwidths)
        for (auto& tensor : frame) check(tensor);
}

// Augmentation keeps the physics: warping the transformed previous frame with the transformed
// motion gives the transformed warp, for all 8 rotations / reflections with a colour permutation.
TEST(TrainingAugmentation, WarpCommutesWithEveryTransform) {
    torch::manual_seed(9);
    const std::int64_t size = 9;
    train::Clip clip{torch::rand({2, 1, 18, size, size}), torch::randn({2, 2, size, size}) * 2.5,
                     torch::ones({2, 1, size, size}), torch::rand({2, 3, size, size})};
    const torch::Tensor warped = train::warpBilinear(clip.reference.narrow(0, 0, 1), clip.motion.narrow(0, 1, 1));
    for (int bits = 0; bits < 8; ++bits) {
        train::Augmentation augmentation;
        augmentation.transpose = bits & 1;
        augmentation.flipX = bits & 2;
        augmentation.flipY = bits & 4;
        augmentation.colours = {2, 0, 1};
        train::Clip transformed = clip;
        train::applyAugmentation(transformed, augmentation);
        // The expected image: the original warp result, transformed as frame 1 of a clip.
        train::Clip expected{clip.samples, clip.motion, clip.valid,
                             torch::cat({clip.reference.narrow(0, 0, 1), warped})};
        train::applyAugmentation(expected, augmentation);
        const torch::Tensor actual = train::warpBilinear(transformed.reference.narrow(0, 0, 1).contiguous(),
                                                         transformed.motion.narrow(0, 1, 1).contiguous());
        EXPECT_LT((actual - expected.reference.narrow(0, 1, 1)).abs().max().item<double>(), 1e-5) << "bits " << bits;
        // Diffuse, specular and albedo follow the reference's colour permutation.
        for (int c = 0; c < 3; ++c) {
            for (int base : {channel::kDiffuse, channel::kSpecular, channel::kAlbedo}) {
                EXPECT_NEAR(transformed.samples.select(2, base + c).sum().item<double>(),
                            clip.samples.select(2, base + augmentation.colours[std::size_t(c)]).sum().item<double>(),
                            1e-3);
            }
        }
    }
}

// runTraining(options) throws affinity::Error whose message contains `words`.
static void expectRejectedNaming(const train::TrainOptions& options, const std::string& words) {
    try {
        train::runTraining(options);
        ADD_FAILURE() << "options accepted; expected an error naming " << words;
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
}

TEST(TrainingOptions, NegativeOrNaNLossWeightsAreRejectedBeforeAnyWork) {
    train::TrainOptions options;
    options.trainDir = "unused-train";
    options.outDir = "unused-out";
    for (double bad : {-0.5, double(NAN)}) {
        options.loss.temporal = bad;
        expectRejectedNaming(options, "loss weights");
        options.loss.temporal = 0.25;
        options.loss.absoluteTemporal = bad;
        EXPECT_THROW(train::runTraining(options), Error);
        options.loss.absoluteTemporal = 0;
        options.loss.coarse = bad;
        EXPECT_THROW(train::runTraining(options), Error);
        options.loss.coarse = 0;
        options.loss.displayed = bad;
        expectRejectedNaming(options, "loss weights");
        options.loss.displayed = 0;
    }
    options.loss.coarseCell = 0;
    EXPECT_THROW(train::runTraining(options), Error);
    options.loss.coarseCell = 8;
    for (double bad : {0.0, -1.0, double(NAN)}) {
        options.loss.firstFrame = bad;
        expectRejectedNaming(options, "first-frame weight");
    }
    EXPECT_FALSE(fs::exists("unused-out"));
}

// Keeping fewer samples than a step may draw would cap every step below --max-spp unseen.
TEST(TrainingOptions, KeepingFewerSamplesThanAStepDrawsIsRejectedBeforeAnyWork) {
    train::TrainOptions options;
    options.trainDir = "unused-train";
    options.outDir = "unused-out";
    options.maxSpp = 8;
    options.keepSpp = 4;
    expectRejectedNaming(options, "--keep-spp");
    options.keepSpp = -1;
    expectRejectedNaming(options, "--keep-spp");
    EXPECT_FALSE(fs::exists("unused-out"));
}

// The slowest test: render a tiny fixed dataset with the sample renderer, train the tiny
// preset on it for 80 steps, and require the validation loss to fall well below its starting value; then
// the exported weights load in the core and match the torch model frame by frame.
TEST(TrainingSmoke, TinyModelLearnsExportsAndMatchesTheCore) {
    const fs::path root = fs::temp_directory_path() / "affinity_training_smoke";
    fs::remove_all(root);
    const std::string renderer = std::string(AFFINITY_BINARY_DIR) + "/core/affinity";
    auto render = [&](const std::string& split, int seed, int referenceSpp) {
        const std::string command = renderer + " render --scene procedural:" + std::to_string(seed) +
                                    " --frames 4 --spp 8 --size 48x48 --reference-spp " + std::to_string(referenceSpp) +
                                    " --seed " + std::to_string(seed) + " --out " +
                                    (root / split / ("seed_" + std::to_string(seed))).string() +
                                    " --compression none > /dev/null 2>&1";
        ASSERT_EQ(std::system(command.c_str()), 0) << command;
    };
    for (int seed : {101, 102, 103, 104}) render("train", seed, 32);
    render("val", 201, 128);

    train::TrainOptions options;
    options.trainDir = (root / "train").string();
    options.valDir = (root / "val").string();
    options.outDir = (root / "run").string();
    options.preset = "tiny";
    options.seed = 1;
    options.steps = 80;
    options.maxMinutes = 4;  // a cap for very slow machines, far above the 80 steps' usual time
    options.threads = 1;     // no OpenMP spinning against other tests running beside it
    options.batch = 4;
    options.crop = 32;
    options.frames = 4;
    options.valEvery = 10;
    options.checkpointEvery = 50;
    options.quiet = true;
    const train::TrainSummary summary = train::runTraining(options);
    std::cout << "smoke training: steps " << summary.lastStep << " in " << summary.seconds << " s, validation loss "
              << summary.initialValLoss << " -> best " << summary.bestValLoss << " (SMAPE " << summary.finalValSmape
              << ", noisy " << summary.finalValNoisySmape << ")\n";
    ASSERT_GE(summary.lastStep, 40);
    ASSERT_GT(summary.initialValLoss, 0);
    EXPECT_LT(summary.bestValLoss, 0.75 * summary.initialValLoss);
    ASSERT_TRUE(fs::exists(summary.bestWeights));
    ASSERT_TRUE(fs::exists(root / "run" / "loss.csv"));

    // Export -> core: Model::fromFile loads it; the core and the torch model agree per frame.
    std::vector<SampleFrame> frames;
    for (const std::string& file : listFrameFiles((root / "val" / "seed_201").string()))
        frames.push_back(readFrame(file));
    const std::vector<std::vector<float>> expected = train::torchDenoiseSequence(summary.bestWeights, frames);
    Denoiser denoiser = test::networkDenoiser(summary.bestWeights);  // against libtorch
    double denoisedSmape = 0, noisySmape = 0;
    for (std::size_t t = 0; t < frames.size(); ++t) {
        const std::vector<float> actual = denoiser.denoise(frames[t]);
        ASSERT_EQ(actual.size(), expected[t].size());
        double worst = 0;
        for (std::size_t i = 0; i < actual.size(); ++i) {
            worst = std::max(worst,
                             std::abs(double(actual[i]) - expected[t][i]) / (std::abs(double(expected[t][i])) + 1e-3));
        }
        EXPECT_LT(worst, 1e-4) << "frame " << t;
        const std::vector<float> noisy = frames[t].meanRadiance();
        denoisedSmape += smape(actual.data(), frames[t].reference().data(), actual.size());
        noisySmape += smape(noisy.data(), frames[t].reference().data(), noisy.size());
    }
    std::cout << "core on the validation sequence: SMAPE " << denoisedSmape / double(frames.size()) << " vs noisy "
              << noisySmape / double(frames.size()) << "\n";

    // --keep-spp holds only the first samples of the 8 rendered per pixel; one step trains on them.
    EXPECT_EQ(summary.trainSpp, 8);
    options.outDir = (root / "kept").string();
    options.steps = 1;
    options.minSpp = options.maxSpp = 2;
    options.keepSpp = 2;
    const train::TrainSummary kept = train::runTraining(options);
    EXPECT_EQ(kept.trainSpp, 2);
    EXPECT_EQ(kept.lastStep, 1);
    EXPECT_TRUE(std::isfinite(kept.finalValLoss));
    fs::remove_all(root);
}
