#pragma once
// End-to-end training of the denoising network (docs/METHOD.md section 7) on per-sample frame
// sequences as the renderer writes them (one folder per sequence, frame_NNNN.exr with a
// reference). Torch-free interface: the CLI (train_main.cpp) and the tests call runTraining.
#include <cstdint>
#include <string>

#include "loss_weights.h"
#include "model_config.h"

namespace affinity::train {

struct TrainOptions {
    std::string trainDir;  // folder of sequence folders (each with frame files + references)
    std::string valDir;    // held-out sequences with clean references (may be empty)
    std::string outDir;    // loss.csv, checkpoint.affw, optimizer.pt, state.txt, best.affw, final.affw
    std::string preset = "tiny";
    std::string initWeights;     // start from this weights file instead of a fresh preset model
    std::uint64_t seed = 1;      // model initialisation and every random choice of the batches
    int steps = 1000;            // total optimisation steps (a resumed run continues up to this)
    double maxMinutes = 0;       // stop earlier after this much wall time in this run (0: no limit)
    int batch = 4;               // crops per step (independent sequences advancing together)
    int crop = 64;               // square crop side, the same window in every frame of a sequence
    int frames = 6;              // frames per training sequence (back-propagation through all of them)
    int minSpp = 2, maxSpp = 8;  // samples per pixel drawn uniformly per step from the rendered ones
    int valSpp = 4;              // samples per pixel for validation (the first valSpp samples)
    double learningRate = 1e-3;
    int lrHalfLife = 0;          // learning rate halves every lrHalfLife steps (0: constant)
    LossWeights loss;            // the loss terms' weights (loss_weights.h); the defaults are the paper's
    double clipNorm = 1.0;       // gradient norm clipping (0: off)
    int valEvery = 50;           // validation and a loss.csv row every valEvery steps
    int checkpointEvery = 100;   // checkpoint every checkpointEvery steps (and at the end)
    int threads = 2;             // torch intra-op threads
    std::string device = "cpu";  // torch device: "cpu", or "cuda" where libtorch was built with CUDA
    // Resource limits, not variants of the recipe: a quick run on part of the data, and more
    // sequences in RAM than whole 16-spp ones fit (the drawn spp stay in minSpp..maxSpp).
    int maxSequences = 0;  // use only the first N training sequences (0: all)
    int keepSpp = 0;       // hold only each training sequence's first N samples per pixel in
                           // memory (0: all; else at least maxSpp)
    bool resume = true;    // continue from outDir's checkpoint when there is one
    bool quiet = false;
};

struct TrainSummary {
    int firstStep = 0;  // step the run started at (> 0 when resumed)
    int trainSpp = 0;   // samples per pixel held in memory per training sequence (the fewest)
    int lastStep = 0;
    double seconds = 0;
    double initialValLoss = -1;  // validation loss at the run's first evaluation (-1: none)
    double finalValLoss = -1;
    double bestValLoss = -1;
    double finalValSmape = -1, finalValNoisySmape = -1;
    std::string bestWeights, finalWeights;
};

// Throws affinity::Error for bad options or data.
TrainSummary runTraining(const TrainOptions& options);

}  // namespace affinity::train
