// `affinity`: the command-line front end. Usage: affinity <command> [options].
#include <algorithm>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "affinity/error.h"
#include "commands.h"

namespace {

const char* const kRenderUsage =
    "usage: affinity render --scene NAME_OR_FILE --frames N --spp S --size WxH --reference-spp R\n"
    "                       --seed K --out DIR [--first-frame F] [--compression none|zip|piz]\n"
    "                       [--feature-convention renderer|cycles] [--previews] [--force]\n"
    "Renders a per-sample frame sequence with its references into DIR (frame_NNNN.exr,\n"
    "scene.json, render_summary.json; with --previews noisy_NNNN.png and reference_NNNN.png).\n"
    "  --scene NAME_OR_FILE   a bundled scene, a scene file, procedural:SEED or procedural-sparks:SEED\n"
    "  --frames N             frames to render (default 8), numbered from --first-frame (default 0)\n"
    "  --spp S                samples per pixel, each stored separately (1..64, default 4)\n"
    "  --size WxH             image size, each side 1..16384 (default 256x256)\n"
    "  --reference-spp R      samples per pixel of the reference, 0 for none (default 1024)\n"
    "  --seed K               random seed (default 0)\n"
    "  --compression C        EXR compression: none, zip or piz (default piz)\n"
    "  --feature-convention C the features as the renderer (default) or Cycles makes them\n"
    "  --previews             also write tone-mapped PNGs\n"
    "  --force                replace the sequence already in DIR\n";

const char* const kDenoiseUsage =
    "usage: affinity denoise --in DIR --out DIR [--model FILE.affw] [--precision auto|fp32|bf16] [--force]\n"
    "Denoises the frames of --in in order into --out (denoised_NNNN.exr, denoised_NNNN.png,\n"
    "denoise_summary.json); inputs are never overwritten.\n"
    "  --model FILE.affw      weights file (default: the built-in model)\n"
    "  --precision P          the network's products: auto (default: bf16 where the CPU has\n"
    "                         AVX512-BF16, else fp32), fp32, or bf16 (CPUs with AVX512-BF16)\n"
    "  --force                write into an --out folder that already exists\n";

void printUsage(std::FILE* to) {
    std::fprintf(to,
                 "usage: affinity <command> [options]\n"
                 "commands:\n"
                 "  render   render a per-sample frame sequence with its references\n"
                 "           --scene NAME_OR_FILE --frames N --spp S --size WxH --reference-spp R\n"
                 "           --seed K --out DIR [--first-frame F] [--compression none|zip|piz]\n"
                 "           [--feature-convention renderer|cycles] [--previews] [--force]\n"
                 "  denoise  denoise a frame sequence: --in DIR --out DIR [--model FILE.affw] [--precision "
                 "auto|fp32|bf16] [--force]\n"
                 "'affinity <command> --help' describes a command's options.\n");
}

// `--help` or `-h` anywhere after a command asks for that command's usage (as most tools read
// it, even where it would be an option's value): checked before the command parses anything,
// so a request for help never starts a run or fails on a missing option.
bool asksForHelp(const std::vector<std::string>& args) {
    return std::any_of(args.begin(), args.end(), [](const std::string& a) { return a == "--help" || a == "-h"; });
}

}  // namespace

int main(int argc, char** argv) {
    std::vector<std::string> args(argv + 1, argv + argc);
    if (args.empty() || args[0] == "-h" || args[0] == "--help") {
        // Asked for: stdout and success; missing: the usage as an error.
        printUsage(args.empty() ? stderr : stdout);
        return args.empty() ? 2 : 0;
    }
    const std::string command = args[0];
    args.erase(args.begin());
    if ((command == "render" || command == "denoise") && asksForHelp(args)) {
        std::fputs(command == "render" ? kRenderUsage : kDenoiseUsage, stdout);
        return 0;
    }
    try {
        if (command == "render") return affinity::cli::renderCommand(args);
        if (command == "denoise") return affinity::cli::denoiseCommand(args);
        std::fprintf(stderr, "affinity: unknown command '%s'\n", command.c_str());
        printUsage(stderr);
        return 2;
    } catch (const affinity::Error& e) {
        std::fprintf(stderr, "affinity %s: error: %s\n", command.c_str(), e.what());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "affinity %s: internal error: %s\n", command.c_str(), e.what());
        return 3;
    }
}
