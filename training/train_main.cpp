// affinity_train: trains the denoising network end to end (docs/TRAINING.md).
//   affinity_train --data DIR --out DIR [options]
// DIR/train and DIR/val hold sequence folders as scripts/make_training_data.sh writes them.
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "affinity/error.h"
#include "trainer.h"

namespace {

constexpr const char* kUsage =
    "usage: affinity_train --data DIR --out DIR [options]\n"
    "  --data DIR          folder with train/ and val/ sequence folders (scripts/make_training_data.sh)\n"
    "  --train DIR         training sequences (default DATA/train)\n"
    "  --val DIR           validation sequences with clean references (default DATA/val if present)\n"
    "  --out DIR           loss.csv, checkpoint.affw, optimizer.pt, state.txt, best.affw, final.affw\n"
    "  --preset NAME       tiny | small | medium | paper (default tiny)\n"
    "  --init FILE.affw    start from these weights instead of a fresh model\n"
    "  --steps N           total steps (default 1000); a resumed run continues up to N\n"
    "  --minutes M         stop this run after M minutes of wall time (default: no limit)\n"
    "  --batch B           crops per step (4)      --crop C      crop side (64)\n"
    "  --frames T          frames per sequence, back-propagated through (6)\n"
    "  --min-spp N --max-spp N   spp drawn uniformly per step (2..8)   --val-spp N   (4)\n"
    "  --lr X              Adam learning rate (1e-3)   --lr-half-life N   halve every N steps (0: off)\n"
    "  --clip X            gradient norm clipping (1; 0: off)\n"
    "  --temporal-weight W weight of the temporal SMAPE term (0.25, the paper's)\n"
    "  --absolute-temporal-weight W  weight of mean |dt O - dt O*| / mean |O*| (0; train_loss.h)\n"
    "  --warped-temporal   dt O = O_t - O_{t-1} warped by the motion, valid pixels only (train_loss.h)\n"
    "  --coarse-weight W   weight of SMAPE of cell means, against dark bias (0; train_loss.h)\n"
    "  --coarse-cell N     cell side of that term, pixels (8)\n"
    "  --first-frame-weight W  weight of a sequence's first frame in the image terms (1; loss_weights.h)\n"
    "  --displayed-weight W  weight of mean |D(O) - D(O*)|, D tone-mapped and gamma-encoded (0; loss_weights.h)\n"
    "  --val-every N (50)  --checkpoint-every N (100)  --threads N (2)  --seed N (1)\n"
    "  --device NAME       cpu (default), or cuda with a CUDA build of libtorch\n"
    "  --max-sequences N   use the first N training sequences only\n"
    "  --keep-spp N        hold only the first N samples per pixel of each training sequence in\n"
    "                      memory (at least --max-spp): half the memory of 16-spp data at 8\n"
    "  --fresh             ignore an existing checkpoint in --out\n"
    "  --export FILE.affw  copy the best (lowest validation loss) weights here at the end\n";

// The options that take a value (each parsed below), space-separated.
constexpr const char* kValueOptions =
    " --data --train --val --out --preset --init --steps --minutes --batch --crop --frames --min-spp"
    " --max-spp --val-spp --lr --lr-half-life --clip --temporal-weight --absolute-temporal-weight"
    " --coarse-weight --coarse-cell --first-frame-weight --displayed-weight --val-every --checkpoint-every --threads "
    "--device --seed"
    " --max-sequences --keep-spp --export ";

}  // namespace

int main(int argc, char** argv) {
    using affinity::train::TrainOptions;
    const std::vector<std::string> args(argv + 1, argv + argc);
    if (args.empty() || args[0] == "--help" || args[0] == "-h") {
        std::cout << kUsage;
        return args.empty() ? 2 : 0;
    }
    TrainOptions options;
    std::string data, exportPath;
    bool valGiven = false;
    try {
        for (std::size_t i = 0; i < args.size(); ++i) {
            const std::string& flag = args[i];
            if (flag == "--warped-temporal") {
                options.loss.warpedTemporal = true;
                continue;
            }
            if (flag == "--fresh") {
                options.resume = false;
                continue;
            }
            // A removed or mistyped switch is named as unknown, not as missing its value.
            if (std::string(kValueOptions).find(" " + flag + " ") == std::string::npos)
                throw affinity::Error("unknown option " + flag);
            if (i + 1 >= args.size()) throw affinity::Error(flag + " needs a value");
            const std::string& value = args[++i];
            auto integer = [&] {
                std::size_t used = 0;
                int parsed = 0;
                try {
                    parsed = std::stoi(value, &used);
                } catch (const std::exception&) {
                    used = 0;
                }
                if (used != value.size() || value.empty())
                    throw affinity::Error(flag + " '" + value + "' is not an integer");
                return parsed;
            };
            auto real = [&] {
                std::size_t used = 0;
                double parsed = 0;
                try {
                    parsed = std::stod(value, &used);
                } catch (const std::exception&) {
                    used = 0;
                }
                if (used != value.size() || value.empty())
                    throw affinity::Error(flag + " '" + value + "' is not a number");
                return parsed;
            };
            if (flag == "--data")
                data = value;
            else if (flag == "--train")
                options.trainDir = value;
            else if (flag == "--val")
                options.valDir = value, valGiven = true;
            else if (flag == "--out")
                options.outDir = value;
            else if (flag == "--preset")
                options.preset = value;
            else if (flag == "--init")
                options.initWeights = value;
            else if (flag == "--steps")
                options.steps = integer();
            else if (flag == "--minutes")
                options.maxMinutes = real();
            else if (flag == "--batch")
                options.batch = integer();
            else if (flag == "--crop")
                options.crop = integer();
            else if (flag == "--frames")
                options.frames = integer();
            else if (flag == "--min-spp")
                options.minSpp = integer();
            else if (flag == "--max-spp")
                options.maxSpp = integer();
            else if (flag == "--val-spp")
                options.valSpp = integer();
            else if (flag == "--lr")
                options.learningRate = real();
            else if (flag == "--lr-half-life")
                options.lrHalfLife = integer();
            else if (flag == "--clip")
                options.clipNorm = real();
            else if (flag == "--temporal-weight")
                options.loss.temporal = real();
            else if (flag == "--absolute-temporal-weight")
                options.loss.absoluteTemporal = real();
            else if (flag == "--coarse-weight")
                options.loss.coarse = real();
            else if (flag == "--coarse-cell")
                options.loss.coarseCell = integer();
            else if (flag == "--first-frame-weight")
                options.loss.firstFrame = real();
            else if (flag == "--displayed-weight")
                options.loss.displayed = real();
            else if (flag == "--val-every")
                options.valEvery = integer();
            else if (flag == "--checkpoint-every")
                options.checkpointEvery = integer();
            else if (flag == "--threads")
                options.threads = integer();
            else if (flag == "--device")
                options.device = value;
            else if (flag == "--seed")
                options.seed = std::uint64_t(integer());
            else if (flag == "--max-sequences")
                options.maxSequences = integer();
            else if (flag == "--keep-spp")
                options.keepSpp = integer();
            else if (flag == "--export")
                exportPath = value;
            else
                throw affinity::Error("unknown option " + flag);
        }
        if (!data.empty()) {
            if (options.trainDir.empty()) options.trainDir = data + "/train";
            if (!valGiven && std::filesystem::is_directory(data + "/val")) options.valDir = data + "/val";
        }
        const affinity::train::TrainSummary summary = affinity::train::runTraining(options);
        std::cout << "trained steps " << summary.firstStep << ".." << summary.lastStep << " in " << int(summary.seconds)
                  << " s; validation loss " << summary.initialValLoss << " -> " << summary.finalValLoss << " (best "
                  << summary.bestValLoss << "), SMAPE " << summary.finalValSmape << " vs noisy "
                  << summary.finalValNoisySmape << "\n";
        if (!exportPath.empty()) {
            std::filesystem::copy_file(summary.bestWeights, exportPath,
                                       std::filesystem::copy_options::overwrite_existing);
            std::cout << "exported " << summary.bestWeights << " -> " << exportPath << "\n";
        }
        return 0;
    } catch (const std::exception& error) {
        std::cerr << "affinity_train: " << error.what() << "\n";
        return 1;
    }
}
