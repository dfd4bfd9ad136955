// `affinity`: the command-line front end. Usage: affinity <command> [options].
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "affinity/error.h"
#include "commands.h"

namespace {

void printUsage() {
    std::fprintf(stderr,
                 "usage: affinity <command> [options]\n"
                 "commands:\n"
                 "  render   render a per-sample frame sequence with its references\n"
                 "           --scene NAME_OR_FILE --frames N --spp S --size WxH --reference-spp R\n"
                 "           --seed K --out DIR [--first-frame F] [--compression none|zip|piz]\n"
                 "           [--feature-convention renderer|cycles] [--previews] [--force]\n"
                 "  denoise  denoise a frame sequence: --in DIR --out DIR [--model FILE.affw] [--precision fp32|bf16] [--force]\n");
}

}  // namespace

int main(int argc, char** argv) {
    std::vector<std::string> args(argv + 1, argv + argc);
    if (args.empty() || args[0] == "-h" || args[0] == "--help") {
        printUsage();
        return args.empty() ? 2 : 0;
    }
    const std::string command = args[0];
    args.erase(args.begin());
    try {
        if (command == "render") return affinity::cli::renderCommand(args);
        if (command == "denoise") return affinity::cli::denoiseCommand(args);
        std::fprintf(stderr, "affinity: unknown command '%s'\n", command.c_str());
        printUsage();
        return 2;
    } catch (const affinity::Error& e) {
        std::fprintf(stderr, "affinity %s: error: %s\n", command.c_str(), e.what());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "affinity %s: internal error: %s\n", command.c_str(), e.what());
        return 3;
    }
}
