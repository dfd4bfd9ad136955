// affinity_model_tool: creates randomly initialised weights files, describes weights files and
// widens a trained model to a larger preset (to fine-tune it from there, as the shipped medium
// model was made).
//   affinity_model_tool init --preset NAME --seed N --out FILE.affw
//   affinity_model_tool describe FILE.affw
//   affinity_model_tool widen --preset NAME --seed N IN.affw OUT.affw
//   affinity_model_tool add-kernel [--bandwidth-scale S] IN.affw OUT.affw
//   affinity_model_tool light-restoration on|off IN.affw OUT.affw
//   affinity_model_tool temporal-gain PERCENT IN.affw OUT.affw
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "affinity/error.h"
#include "affinity/weights.h"
#include "model_config.h"
#include "model_surgery.h"
#include "network/network.h"
#include "torch_reference.h"

namespace affinity::train {
namespace {

constexpr const char* kUsage =
    "usage: affinity_model_tool init --preset NAME --seed N --out FILE.affw\n"
    "       affinity_model_tool describe FILE.affw\n"
    "       affinity_model_tool widen --preset NAME --seed N IN.affw OUT.affw   (same function, the preset's wider\n"
    "           layers; the new channels' incoming weights initialised with seed N)\n"
    "       affinity_model_tool add-kernel [--bandwidth-scale S] IN.affw OUT.affw   (one more dilated kernel,\n"
    "           the last and widest; it starts as a copy of the old last one, bandwidth x S, default 2)\n"
    "       affinity_model_tool light-restoration on|off IN.affw OUT.affw   (whether denoising restores the\n"
    "           input's light after the kernels, docs/MODEL.md section 10; the weights unchanged)\n"
    "       affinity_model_tool temporal-gain PERCENT IN.affw OUT.affw   (the temporal taps' weights times\n"
    "           PERCENT / 100, docs/MODEL.md section 7; 100 leaves the file as trained)\n";

std::string joined(const std::vector<int>& widths) {
    std::string text;
    for (int width : widths) text += (text.empty() ? "" : "-") + std::to_string(width);
    return text;
}

// `value` as a non-negative integer; throws affinity::Error naming `what` (command and option).
std::uint64_t nonNegativeInteger(const std::string& what, const std::string& value) {
    std::size_t used = 0;
    std::uint64_t number = 0;
    try {
        number = std::stoull(value, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    if (used != value.size() || value.empty() || value[0] == '-')
        throw Error(what + " '" + value + "' is not a non-negative integer");
    return number;
}

int runInit(const std::vector<std::string>& args) {
    std::string preset = "small", out;
    std::uint64_t seed = 0;
    for (std::size_t i = 0; i < args.size(); ++i) {
        const std::string& flag = args[i];
        if (i + 1 >= args.size()) throw Error("init: " + flag + " needs a value");
        const std::string& value = args[++i];
        if (flag == "--preset") {
            preset = value;
        } else if (flag == "--seed") {
            seed = nonNegativeInteger("init: --seed", value);
        } else if (flag == "--out") {
            out = value;
        } else {
            throw Error("init: unknown option " + flag);
        }
    }
    if (out.empty()) throw Error("init: --out FILE is required");
    const ModelConfig config = presetConfig(preset);
    writeInitialModel(config, seed, out);
    std::cout << "wrote " << out << ": preset " << preset << ", seed " << seed << ", " << parameterCount(config)
              << " parameters\n";
    return 0;
}

int runDescribe(const std::vector<std::string>& args) {
    if (args.size() != 1) throw Error("describe: expected exactly one weights file");
    const Weights weights = Weights::fromFile(args[0]);
    const ModelConfig config = configFromWeights(weights);
    std::cout << args[0] << "\n";
    std::cout << "  embedding      18-" << joined(config.embedWidths) << " (E = " << config.embeddingChannels()
              << ")\n";
    for (std::size_t l = 0; l < config.encoder.size(); ++l) {
        std::cout << "  level " << l << "        encoder " << joined(config.encoder[l].widths) << ", decoder "
                  << joined(config.decoder[l].widths) << "\n";
    }
    std::cout << "  bottleneck     " << joined(config.bottleneck.widths) << "\n";
    std::cout << "  kernels        K = " << config.kernels << ", F = " << config.affinityFeatures
              << ", T = " << config.kernelSize << " (head P = " << config.headChannels() << ")\n";
    std::cout << "  light restoration " << (config.lightRestoration ? "on" : "off") << "\n";
    std::cout << "  temporal gain  " << config.temporalGainPercent << " %\n";
    std::cout << "  parameters     " << parameterCount(config) << "\n";
    const FlopCount flops = flopCount(config);
    char line[256];
    std::snprintf(line, sizeof line, "  FLOPs / pixel  embedding %.0f per sample, U-Net %.0f, filters %.0f\n",
                  flops.embeddingPerSample, flops.unetPerPixel, flops.filterPerPixel);
    std::cout << line;
    for (int spp : {1, 2, 4, 8}) {
        std::snprintf(line, sizeof line, "                 total at %d spp: %.0f (%.3f GFLOP per 1920x1080 frame)\n",
                      spp, flops.perPixel(spp), flops.perPixel(spp) * 1920.0 * 1080.0 * 1e-9);
        std::cout << line;
    }
    return 0;
}

int runWiden(const std::vector<std::string>& args) {
    std::string preset;
    std::uint64_t seed = 0;
    std::vector<std::string> files;
    for (std::size_t i = 0; i < args.size(); ++i) {
        const std::string& flag = args[i];
        if (flag == "--preset" || flag == "--seed") {
            if (i + 1 >= args.size()) throw Error("widen: " + flag + " needs a value");
            if (flag == "--preset")
                preset = args[i + 1];
            else
                seed = nonNegativeInteger("widen: --seed", args[i + 1]);
            ++i;
        } else {
            files.push_back(flag);
        }
    }
    if (preset.empty() || files.size() != 2) throw Error("widen: expected --preset NAME [--seed N] IN.affw OUT.affw");
    if (files[0] == files[1]) throw Error("widen: the output must not overwrite the input");
    const Weights trained = Weights::fromFile(files[0]);
    const std::string freshPath = files[1] + ".fresh.tmp";
    writeInitialModel(presetConfig(preset), seed, freshPath);
    std::vector<NamedTensor> tensors;
    try {
        tensors = widened(trained, Weights::fromFile(freshPath));
    } catch (...) {
        std::remove(freshPath.c_str());
        throw;
    }
    std::remove(freshPath.c_str());
    writeWeightsFile(files[1], tensors);
    std::cout << "wrote " << files[1] << ": " << files[0] << " widened to preset " << preset << " (seed " << seed
              << ")\n";
    return 0;
}

int runAddKernel(const std::vector<std::string>& args) {
    double scale = 2.0;
    std::vector<std::string> files;
    for (std::size_t i = 0; i < args.size(); ++i) {
        if (args[i] == "--bandwidth-scale") {
            if (i + 1 >= args.size()) throw Error("add-kernel: --bandwidth-scale needs a value");
            const std::string& value = args[++i];
            std::size_t used = 0;
            try {
                scale = std::stod(value, &used);
            } catch (const std::exception&) {
                used = 0;
            }
            if (used != value.size() || value.empty())
                throw Error("add-kernel: --bandwidth-scale '" + value + "' is not a number");
        } else {
            files.push_back(args[i]);
        }
    }
    if (files.size() != 2) throw Error("add-kernel: expected [--bandwidth-scale S] IN.affw OUT.affw");
    if (files[0] == files[1]) throw Error("add-kernel: the output must not overwrite the input");
    writeWeightsFile(files[1], withKernelAdded(Weights::fromFile(files[0]), scale));
    std::cout << "wrote " << files[1] << ": " << files[0] << " with one more kernel (bandwidth scale " << scale
              << ")\n";
    return 0;
}

int runLightRestoration(const std::vector<std::string>& args) {
    if (args.size() != 3 || (args[0] != "on" && args[0] != "off"))
        throw Error("light-restoration: expected on|off IN.affw OUT.affw");
    if (args[1] == args[2]) throw Error("light-restoration: the output must not overwrite the input");
    writeWeightsFile(args[2], withLightRestoration(Weights::fromFile(args[1]), args[0] == "on"));
    std::cout << "wrote " << args[2] << ": " << args[1] << " with light restoration " << args[0] << "\n";
    return 0;
}

int runTemporalGain(const std::vector<std::string>& args) {
    if (args.size() != 3) throw Error("temporal-gain: expected PERCENT IN.affw OUT.affw");
    // Anything above the largest gain reads as one past it, which withTemporalGain refuses.
    const int percent = int(std::min<std::uint64_t>(nonNegativeInteger("temporal-gain: PERCENT", args[0]),
                                                    std::uint64_t(kMaxTemporalGainPercent) + 1));
    if (args[1] == args[2]) throw Error("temporal-gain: the output must not overwrite the input");
    writeWeightsFile(args[2], withTemporalGain(Weights::fromFile(args[1]), percent));
    std::cout << "wrote " << args[2] << ": " << args[1] << " with temporal gain " << percent << " %\n";
    return 0;
}

}  // namespace
}  // namespace affinity::train

int main(int argc, char** argv) {
    const std::vector<std::string> args(argv + 1, argv + argc);
    if (args.empty() || args[0] == "--help" || args[0] == "-h") {
        std::cout << affinity::train::kUsage;
        return args.empty() ? 2 : 0;
    }
    const std::vector<std::string> rest(args.begin() + 1, args.end());
    try {
        if (args[0] == "init") return affinity::train::runInit(rest);
        if (args[0] == "describe") return affinity::train::runDescribe(rest);
        if (args[0] == "widen") return affinity::train::runWiden(rest);
        if (args[0] == "add-kernel") return affinity::train::runAddKernel(rest);
        if (args[0] == "light-restoration") return affinity::train::runLightRestoration(rest);
        if (args[0] == "temporal-gain") return affinity::train::runTemporalGain(rest);
        std::cerr << "affinity_model_tool: unknown command '" << args[0] << "'\n" << affinity::train::kUsage;
        return 2;
    } catch (const affinity::Error& error) {
        std::cerr << "affinity_model_tool: " << error.what() << "\n";
        return 1;
    }
}
