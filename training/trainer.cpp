#include "trainer.h"

#include <torch/types.h>

#include <vector>

#include <torch/nn/utils/clip_grad.h>
#include <torch/optim/adam.h>
#include <torch/serialize.h>
#include <torch/utils.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <numeric>
#include <random>
#include <sstream>
#include <thread>

#include "affinity/error.h"
#include "affinity/features.h"
#include "affinity/frame_io.h"
#include "affinity/weights.h"
#include "affinity_model.h"
#include "model_weights.h"
#include "train_augment.h"
#include "train_loss.h"

namespace fs = std::filesystem;

namespace affinity::train {
namespace {

// One rendered sequence in memory. Samples are kept in half precision (they are converted to
// float per batch); everything else in float.
struct Sequence {
    std::string name;
    torch::Tensor samples;    // [T, S, 18, H, W] half
    torch::Tensor motion;     // [T, 2, H, W]
    torch::Tensor valid;      // [T, 1, H, W]
    torch::Tensor reference;  // [T, 3, H, W]
    std::int64_t frames() const { return samples.size(0); }
    std::int64_t spp() const { return samples.size(1); }
    std::int64_t height() const { return samples.size(3); }
    std::int64_t width() const { return samples.size(4); }
};

// Sequence folders (those holding frame files) under `root`, sorted by name.
std::vector<std::string> sequenceFolders(const std::string& root) {
    if (!fs::is_directory(root)) throw Error("training data folder " + root + " does not exist");
    std::vector<std::string> folders;
    for (const fs::directory_entry& entry : fs::directory_iterator(root)) {
        // render_summary.json is the renderer's last write: a sequence still rendering is skipped.
        if (entry.is_directory() && fs::exists(entry.path() / "render_summary.json")) {
            folders.push_back(entry.path().string());
        }
    }
    std::sort(folders.begin(), folders.end());
    return folders;
}

// `keepSpp` > 0 keeps only the first keepSpp samples of every pixel.
Sequence loadSequence(const std::string& folder, int keepSpp) {
    const std::vector<std::string> files = listFrameFiles(folder);
    if (files.empty()) throw Error(folder + ": no frame files");
    std::vector<torch::Tensor> samples, motion, valid, reference;
    int width = 0, height = 0, spp = 0;
    for (const std::string& file : files) {
        const SampleFrame frame = readFrame(file);
        if (!frame.hasReference()) throw Error(file + ": no reference (render with --reference-spp)");
        if (samples.empty()) {
            width = frame.width(), height = frame.height(), spp = frame.spp();
        } else if (frame.width() != width || frame.height() != height || frame.spp() != spp) {
            throw Error(file + ": size or spp differs from the sequence's first frame");
        }
        auto view = [](const std::vector<float>& data, std::vector<std::int64_t> shape) {
            return torch::from_blob(const_cast<float*>(data.data()), shape, torch::kFloat);
        };
        const std::int64_t kept = keepSpp > 0 ? std::min(keepSpp, spp) : spp;
        samples.push_back(view(frame.samples(), {height, width, spp, kFeatureCount})
                              .narrow(2, 0, kept)
                              .permute({2, 3, 0, 1})
                              .clamp(-65000.0, 65000.0)  // half's range; larger values are rare fireflies
                              .to(torch::kHalf)
                              .contiguous());
        motion.push_back(view(frame.motion(), {height, width, 2}).permute({2, 0, 1}).clone());
        valid.push_back(view(frame.valid(), {1, height, width}).clone());
        reference.push_back(view(frame.reference(), {height, width, 3}).permute({2, 0, 1}).clone());
    }
    Sequence sequence;
    sequence.name = fs::path(folder).filename().string();
    sequence.samples = torch::stack(samples);
    sequence.motion = torch::stack(motion);
    sequence.valid = torch::stack(valid);
    sequence.reference = torch::stack(reference);
    return sequence;
}

// Loads sequences on several threads (frame decoding dominates); the first error is rethrown.
std::vector<Sequence> loadSequences(const std::vector<std::string>& folders, int keepSpp = 0) {
    std::vector<Sequence> sequences(folders.size());
    std::vector<std::string> errors(folders.size());
    std::atomic<std::size_t> next{0};
    const unsigned workers = std::max(1u, std::min(8u, std::thread::hardware_concurrency()));
    std::vector<std::thread> threads;
    for (unsigned w = 0; w < workers; ++w) {
        threads.emplace_back([&] {
            for (std::size_t i = next++; i < folders.size(); i = next++) {
                try {
                    sequences[i] = loadSequence(folders[i], keepSpp);
                } catch (const std::exception& error) {
                    errors[i] = error.what();
                }
            }
        });
    }
    for (std::thread& thread : threads) thread.join();
    for (const std::string& error : errors) {
        if (!error.empty()) throw Error(error);
    }
    return sequences;
}

// A batch: per frame, the model's inputs and the reference.
struct Batch {
    std::vector<FrameInput> frames;
    std::vector<torch::Tensor> references;
};

Clip cutClip(const Sequence& sequence, std::int64_t firstFrame, std::int64_t frameCount, std::int64_t y, std::int64_t x,
             std::int64_t size, const std::vector<std::int64_t>& sampleIndices) {
    const torch::Tensor index = torch::tensor(sampleIndices, torch::kLong);
    Clip clip;
    clip.samples = sequence.samples.narrow(0, firstFrame, frameCount)
                       .index_select(1, index)
                       .narrow(3, y, size)
                       .narrow(4, x, size)
                       .to(torch::kFloat);
    clip.motion = sequence.motion.narrow(0, firstFrame, frameCount).narrow(2, y, size).narrow(3, x, size);
    clip.valid = sequence.valid.narrow(0, firstFrame, frameCount).narrow(2, y, size).narrow(3, x, size);
    clip.reference = sequence.reference.narrow(0, firstFrame, frameCount).narrow(2, y, size).narrow(3, x, size);
    return clip;
}

Batch assemble(std::vector<Clip>& clips, const torch::Device& device) {
    Batch batch;
    const std::int64_t frameCount = clips[0].samples.size(0);
    for (std::int64_t t = 0; t < frameCount; ++t) {
        std::vector<torch::Tensor> samples, motion, valid, reference;
        for (const Clip& clip : clips) {
            samples.push_back(clip.samples[t]);
            motion.push_back(clip.motion[t]);
            valid.push_back(clip.valid[t]);
            reference.push_back(clip.reference[t]);
        }
        batch.frames.push_back({torch::stack(samples).contiguous().to(device),
                                torch::stack(motion).contiguous().to(device),
                                torch::stack(valid).contiguous().to(device)});
        batch.references.push_back(torch::stack(reference).contiguous().to(device));
    }
    return batch;
}

// A random training batch: `batch` sequences (with repetition), one random window of frames,
// one random square crop per sequence (the same in all its frames), one spp for the batch drawn
// uniformly in [minSpp, maxSpp] as a random subset of each sequence's rendered samples.
Batch sampleBatch(const std::vector<Sequence>& data, const TrainOptions& options, std::mt19937_64& rng,
                  const torch::Device& device) {
    std::int64_t frameCount = options.frames, size = options.crop, spp = 64;
    for (const Sequence& sequence : data) {
        frameCount = std::min(frameCount, sequence.frames());
        size = std::min({size, sequence.height(), sequence.width()});
        spp = std::min(spp, sequence.spp());
    }
    const std::int64_t lowSpp = std::min<std::int64_t>(options.minSpp, spp);
    const std::int64_t highSpp = std::min<std::int64_t>(options.maxSpp, spp);
    const std::int64_t batchSpp = std::uniform_int_distribution<int>(int(lowSpp), int(highSpp))(rng);
    std::vector<Clip> clips;
    for (int b = 0; b < options.batch; ++b) {
        const Sequence& sequence = data[std::uniform_int_distribution<std::size_t>(0, data.size() - 1)(rng)];
        const std::int64_t first = std::uniform_int_distribution<std::int64_t>(0, sequence.frames() - frameCount)(rng);
        const std::int64_t y = std::uniform_int_distribution<std::int64_t>(0, sequence.height() - size)(rng);
        const std::int64_t x = std::uniform_int_distribution<std::int64_t>(0, sequence.width() - size)(rng);
        std::vector<std::int64_t> indices(std::size_t(sequence.spp()));
        std::iota(indices.begin(), indices.end(), 0);
        std::shuffle(indices.begin(), indices.end(), rng);
        indices.resize(std::size_t(batchSpp));
        Clip clip = cutClip(sequence, first, frameCount, y, x, size, indices);
        applyAugmentation(clip, randomAugmentation(rng));
        clips.push_back(std::move(clip));
    }
    return assemble(clips, device);
}

// A whole validation sequence (every frame, full size) at its first `spp` samples.
Batch wholeSequence(const Sequence& sequence, int spp, const torch::Device& device) {
    std::vector<std::int64_t> indices(std::size_t(std::min<std::int64_t>(spp, sequence.spp())));
    std::iota(indices.begin(), indices.end(), 0);
    std::vector<Clip> clips{cutClip(sequence, 0, sequence.frames(), 0, 0, sequence.height(), indices)};
    // cutClip crops a square: take the full width explicitly for non-square frames.
    if (sequence.width() != sequence.height()) {
        const torch::Tensor index = torch::tensor(indices, torch::kLong);
        clips[0] = {sequence.samples.index_select(1, index).to(torch::kFloat), sequence.motion, sequence.valid,
                    sequence.reference};
    }
    return assemble(clips, device);
}

struct ForwardResult {
    LossTerms loss;
    torch::Tensor noisySmape;  // SMAPE of the noisy input over the sequence
};

ForwardResult forwardBatch(AffinityModel& model, const Batch& batch, const LossWeights& weights) {
    RecurrentState state;
    std::vector<torch::Tensor> outputs;
    std::vector<std::vector<torch::Tensor>> bandwidths;
    torch::Tensor noisy = torch::zeros({}, batch.references[0].options());
    for (std::size_t t = 0; t < batch.frames.size(); ++t) {
        FrameResult result = model->forwardFrame(batch.frames[t], state);
        outputs.push_back(result.output);
        std::vector<torch::Tensor> frameBandwidths;
        for (const KernelParams& kernel : result.kernels) frameBandwidths.push_back(kernel.bandwidth);
        frameBandwidths.push_back(result.temporalBandwidth);
        bandwidths.push_back(std::move(frameBandwidths));
        noisy = noisy + smapeLoss(result.noisy.detach(), batch.references[t]);
    }
    std::vector<FrameMotion> motions;
    for (const FrameInput& frame : batch.frames) motions.push_back({frame.motion, frame.valid});
    return {sequenceLoss(outputs, batch.references, bandwidths, weights, motions), noisy / double(batch.frames.size())};
}

struct Validation {
    double loss = 0, smape = 0, temporal = 0, absoluteTemporal = 0, noisySmape = 0, coarse = 0;
};

// loss is the training loss without the regulariser.
Validation validate(AffinityModel& model, const std::vector<Batch>& batches, const LossWeights& weights) {
    Validation result;
    if (batches.empty()) return result;
    torch::NoGradGuard noGrad;
    model->eval();
    for (const Batch& batch : batches) {
        const ForwardResult forward = forwardBatch(model, batch, weights);
        result.loss += forward.loss.total.item<double>() - kRegulariserWeight * forward.loss.regulariser.item<double>();
        result.smape += forward.loss.spatial.item<double>();
        result.temporal += forward.loss.temporal.item<double>();
        result.absoluteTemporal += forward.loss.absoluteTemporal.item<double>();
        result.noisySmape += forward.noisySmape.item<double>();
        result.coarse += forward.loss.coarse.item<double>();
    }
    model->train();
    const double n = double(batches.size());
    return {result.loss / n,       result.smape / n, result.temporal / n, result.absoluteTemporal / n,
            result.noisySmape / n, result.coarse / n};
}

void checkOptions(const TrainOptions& o) {
    if (o.trainDir.empty() || o.outDir.empty()) throw Error("training needs a data folder and an output folder");
    if (o.steps < 1 || o.batch < 1 || o.crop < 8 || o.frames < 1 || o.minSpp < 1 || o.maxSpp < o.minSpp ||
        o.valSpp < 1 || o.learningRate <= 0 || o.valEvery < 1 || o.checkpointEvery < 1 || o.threads < 1 ||
        !(o.loss.temporal >= 0) || !(o.loss.absoluteTemporal >= 0) || !(o.loss.coarse >= 0) || o.loss.coarseCell < 1 ||
        !(o.loss.displayed >= 0) || !(o.loss.firstFrame > 0)) {
        throw Error(
            "training options out of range (steps, batch, crop >= 8, frames, spp, lr, intervals, threads, "
            "loss weights >= 0, first-frame weight > 0, coarse cell >= 1)");
    }
    if (o.keepSpp < 0 || (o.keepSpp > 0 && o.keepSpp < o.maxSpp))
        throw Error("--keep-spp must be 0 (all samples) or at least --max-spp (" + std::to_string(o.maxSpp) + ")");
}

double learningRateAt(const TrainOptions& options, int step) {
    if (options.lrHalfLife <= 0) return options.learningRate;
    return options.learningRate * std::pow(0.5, double(step) / options.lrHalfLife);
}

}  // namespace

TrainSummary runTraining(const TrainOptions& options) {
    checkOptions(options);
    const LossWeights& lossWeights = options.loss;
    torch::set_num_threads(options.threads);
    const torch::Device device(options.device);  // "cpu", "cuda", "cuda:1", ...
    const auto start = std::chrono::steady_clock::now();
    auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(); };
    auto say = [&](const std::string& text) {
        if (!options.quiet) std::cout << text << std::endl;
    };
    // libtorch's CPU ops each open an OpenMP region; with sleeping workers every region pays a
    // futex wake-up, and a step of our many small ops is much slower (docs/TRAINING.md, "Threads
    // that sleep between ops").
    const char* waitPolicy = std::getenv("OMP_WAIT_POLICY");
    if (options.threads > 1 && options.device == "cpu" && waitPolicy && std::string(waitPolicy) == "passive")
        say("note: OMP_WAIT_POLICY=passive makes CPU training steps about twice as slow; unset it for a training run");
    fs::create_directories(options.outDir);
    const fs::path out(options.outDir);

    // Data.
    std::vector<std::string> trainFolders = sequenceFolders(options.trainDir);
    if (options.maxSequences > 0 && trainFolders.size() > std::size_t(options.maxSequences)) {
        trainFolders.resize(std::size_t(options.maxSequences));
    }
    if (trainFolders.empty()) throw Error("no training sequences in " + options.trainDir);
    std::vector<Sequence> train = loadSequences(trainFolders, options.keepSpp);
    std::vector<Batch> val;
    std::vector<std::string> valNames;
    if (!options.valDir.empty()) {
        for (const Sequence& sequence : loadSequences(sequenceFolders(options.valDir))) {
            val.push_back(wholeSequence(sequence, options.valSpp, device));
            valNames.push_back(sequence.name);
        }
    }
    std::int64_t trainSpp = train.front().spp();
    for (const Sequence& sequence : train) trainSpp = std::min(trainSpp, sequence.spp());
    say("training on " + std::to_string(train.size()) + " sequences (" + std::to_string(trainSpp) +
        " samples per pixel held), validating on " + std::to_string(val.size()) + " (loaded in " +
        std::to_string(int(elapsed())) + " s)");

    // Model and optimiser, possibly resumed.
    const fs::path checkpoint = out / "checkpoint.affw", optimizerFile = out / "optimizer.pt",
                   stateFile = out / "state.txt", csvFile = out / "loss.csv";
    int step = 0;
    double bestVal = -1;
    const bool resuming =
        options.resume && fs::exists(checkpoint) && fs::exists(optimizerFile) && fs::exists(stateFile);
    AffinityModel model{nullptr};
    if (resuming) {
        model = modelFromWeights(Weights::fromFile(checkpoint.string()));
        std::ifstream state(stateFile);
        if (!(state >> step >> bestVal)) throw Error(stateFile.string() + ": unreadable");
    } else if (!options.initWeights.empty()) {
        model = modelFromWeights(Weights::fromFile(options.initWeights));
    } else {
        model = makeModel(presetConfig(options.preset), options.seed);
    }
    model->to(device);
    model->train();
    torch::optim::Adam optimizer(model->parameters(), torch::optim::AdamOptions(options.learningRate));
    if (resuming) {
        torch::load(optimizer, optimizerFile.string());
        say("resumed from step " + std::to_string(step));
    }
    const bool newCsv = !resuming || !fs::exists(csvFile);
    std::ofstream csv(csvFile, newCsv ? std::ios::trunc : std::ios::app);
    if (newCsv) {
        csv << "step,elapsed_s,lr,train_loss,train_smape,train_temporal,train_regulariser,train_noisy_smape,"
               "val_loss,val_smape,val_temporal,val_noisy_smape,val_absolute_temporal,val_coarse\n";
    }

    TrainSummary summary;
    summary.firstStep = step;
    summary.trainSpp = int(trainSpp);
    summary.bestWeights = (out / "best.affw").string();
    summary.finalWeights = (out / "final.affw").string();
    double elapsedBefore = 0;
    {
        std::ifstream state(stateFile);
        int ignoredStep = 0;
        double ignoredBest = 0;
        if (resuming && (state >> ignoredStep >> ignoredBest >> elapsedBefore)) {
        } else {
            elapsedBefore = 0;
        }
    }

    auto saveCheckpoint = [&] {
        exportWeights(model, checkpoint.string());
        torch::save(optimizer, (out / "optimizer.pt.tmp").string());
        fs::rename(out / "optimizer.pt.tmp", optimizerFile);
        std::ofstream state(out / "state.txt.tmp");
        state << step << " " << bestVal << " " << elapsedBefore + elapsed() << "\n";
        state.close();
        fs::rename(out / "state.txt.tmp", stateFile);
    };

    auto evaluate = [&](double trainLoss, double trainSmape, double trainTemporal, double trainReg, double trainNoisy) {
        const Validation v = validate(model, val, lossWeights);
        char line[512];
        std::snprintf(line, sizeof line, "%d,%.1f,%.3g,%.6f,%.6f,%.6f,%.4f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f\n", step,
                      elapsedBefore + elapsed(), learningRateAt(options, step), trainLoss, trainSmape, trainTemporal,
                      trainReg, trainNoisy, v.loss, v.smape, v.temporal, v.noisySmape, v.absoluteTemporal, v.coarse);
        csv << line;
        csv.flush();
        if (!val.empty()) {
            if (summary.initialValLoss < 0) summary.initialValLoss = v.loss;
            summary.finalValLoss = v.loss;
            summary.finalValSmape = v.smape;
            summary.finalValNoisySmape = v.noisySmape;
            if (bestVal < 0 || v.loss < bestVal) {
                bestVal = v.loss;
                exportWeights(model, summary.bestWeights);
            }
        }
        std::snprintf(line, sizeof line,
                      "step %5d  %6.0f s  train %.4f (smape %.4f, noisy %.4f)  val %.4f (smape %.4f, temporal "
                      "%.4f, noisy %.4f)",
                      step, elapsedBefore + elapsed(), trainLoss, trainSmape, trainNoisy, v.loss, v.smape, v.temporal,
                      v.noisySmape);
        say(line);
    };

    if (step == 0) evaluate(NAN, NAN, NAN, NAN, NAN);
    double sumLoss = 0, sumSmape = 0, sumTemporal = 0, sumReg = 0, sumNoisy = 0;
    int counted = 0;
    while (step < options.steps) {
        if (options.maxMinutes > 0 && elapsed() > options.maxMinutes * 60.0) {
            say("time limit reached");
            break;
        }
        // Every random choice of step s comes from (seed, s): a resumed run draws the same batches.
        std::mt19937_64 rng(options.seed * 0x9E3779B97F4A7C15ULL + std::uint64_t(step));
        const Batch batch = sampleBatch(train, options, rng, device);
        for (auto& group : optimizer.param_groups()) {
            static_cast<torch::optim::AdamOptions&>(group.options()).lr(learningRateAt(options, step));
        }
        optimizer.zero_grad();
        const ForwardResult forward = forwardBatch(model, batch, lossWeights);
        const double lossValue = forward.loss.total.item<double>();
        if (std::isfinite(lossValue)) {
            forward.loss.total.backward();
            if (options.clipNorm > 0) torch::nn::utils::clip_grad_norm_(model->parameters(), options.clipNorm);
            optimizer.step();
            sumLoss += lossValue;
            sumSmape += forward.loss.spatial.item<double>();
            sumTemporal += forward.loss.temporal.item<double>();
            sumReg += forward.loss.regulariser.item<double>();
            sumNoisy += forward.noisySmape.item<double>();
            ++counted;
        } else {
            say("step " + std::to_string(step) + ": non-finite loss, skipped");
        }
        ++step;
        if (step % options.valEvery == 0 || step == options.steps) {
            const double n = std::max(counted, 1);
            evaluate(sumLoss / n, sumSmape / n, sumTemporal / n, sumReg / n, sumNoisy / n);
            sumLoss = sumSmape = sumTemporal = sumReg = sumNoisy = 0;
            counted = 0;
        }
        if (step % options.checkpointEvery == 0) saveCheckpoint();
    }
    if (counted > 0) {
        const double n = counted;
        evaluate(sumLoss / n, sumSmape / n, sumTemporal / n, sumReg / n, sumNoisy / n);
    }
    saveCheckpoint();
    exportWeights(model, summary.finalWeights);
    if (val.empty()) exportWeights(model, summary.bestWeights);
    summary.lastStep = step;
    summary.seconds = elapsed();
    summary.bestValLoss = bestVal;
    return summary;
}

}  // namespace affinity::train
