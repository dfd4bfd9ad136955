// `affinity denoise`: denoises a sequence folder of frame files in order, writing float EXR
// and tone-mapped PNG per frame, and a summary with timings and, where the frames carry a
// reference, the error of the noisy input and of the output.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "affinity/atomic_file.h"
#include "affinity/denoise_file.h"
#include "affinity/denoiser.h"
#include "affinity/error.h"
#include "affinity/frame_io.h"
#include "affinity/image_io.h"
#include "affinity/metrics.h"
#include "arguments.h"
#include "commands.h"
#include "interrupt.h"
#include "output_folder.h"
#include "progress_bar.h"

namespace affinity::cli {

namespace fs = std::filesystem;

namespace {

// "denoised_0007" for the input frame_0007.exr: outputs follow the input files, so that no two
// inputs share an output whatever frame numbers the files hold.
std::string outputStem(const std::string& input) {
    const std::string name = fs::path(input).stem().string();
    return "denoised_" + name.substr(name.find('_') + 1);
}

nlohmann::json errors(const std::vector<float>& image, const std::vector<float>& reference) {
    return {{"smape", smape(image.data(), reference.data(), image.size())},
            {"relmse", relativeMse(image.data(), reference.data(), image.size())},
            {"psnr", tonemappedPsnr(image.data(), reference.data(), image.size())}};
}

}  // namespace

int denoiseCommand(const std::vector<std::string>& args) {
    const Arguments a(args, {"--in", "--out", "--model", "--precision"}, {"--force"});
    const Precision precision = precisionFromName(a.has("--precision") ? a.text("--precision") : "auto");
    const fs::path in = a.text("--in"), out = a.text("--out");
    const std::vector<std::string> frames = listFrameFiles(in.string());
    if (frames.empty()) throw Error("input folder " + in.string() + " holds no frame files (frame_NNNN.exr)");
    std::error_code same;
    if (fs::exists(out) && fs::equivalent(in, out, same))
        throw Error("output folder must differ from the input folder " + in.string() +
                    ": inputs are never overwritten");
    if (fs::exists(out) && !fs::is_directory(out))
        throw Error("output " + out.string() + " exists and is not a folder");
    if (fs::is_directory(out) && !a.flag("--force"))
        for (const auto& entry : fs::directory_iterator(out))
            if (entry.path().filename().string().rfind("denoised_", 0) == 0)
                throw Error("output folder " + out.string() +
                            " already holds denoised frames; pass --force to overwrite them");
    // The model is read before the output folder is made: a refused run leaves nothing behind.
    Denoiser denoiser(a.has("--model") ? Model::fromFile(a.text("--model"), precision) : Model::builtIn(precision));
    // Before anything is written: a signal from here on leaves what was finished, nothing half-made.
    installInterruptHandlers();
    const OutputFolder folder(out);
    denoiser.setInterruptCheck(interruptRequested);

    nlohmann::json perFrame = nlohmann::json::array();
    ProgressBar bar("denoise");
    double totalSeconds = 0.0;
    for (std::size_t i = 0; i < frames.size() && !interruptRequested(); ++i) {
        // The samples go straight into memory the denoiser lends, which serves its later stages
        // once they are embedded: a frame's samples are not held beside all of its maps.
        DenoiseReport report;
        DenoisedFile file;
        try {
            file = denoiseFrameFile(denoiser, frames[i], NoisyMean::WithReference, &report);
        } catch (const Interrupted&) {
            break;
        }
        const double seconds = file.denoiseMilliseconds / 1e3;
        const SampleFrame& frame = file.frame;
        const std::vector<float>& denoised = file.denoised;
        totalSeconds += seconds;
        const std::string stem = outputStem(frames[i]);
        writeRgbExr((out / (stem + ".exr")).string(), frame.width(), frame.height(), denoised.data());
        writeTonemappedPng((out / (stem + ".png")).string(), frame.width(), frame.height(), denoised.data());
        nlohmann::json entry = {{"input", fs::path(frames[i]).filename().string()},
                                {"output", stem + ".exr"},
                                {"frame", frame.info.frameIndex},
                                {"milliseconds", seconds * 1e3},
                                {"used_history", report.usedHistory},
                                {"invalid_radiance", report.invalidRadiance},
                                {"exposure", report.exposure}};
        if (!report.resetReason.empty()) entry["reset_reason"] = report.resetReason;
        if (report.invalidRadiance > 0)
            std::fprintf(stderr, "\nwarning: %s: %lld NaN/Inf/negative/huge radiance values read as 0\n",
                         frames[i].c_str(), report.invalidRadiance);
        if (frame.hasReference()) {
            entry["noisy"] = errors(file.noisy, frame.reference());
            entry["denoised"] = errors(denoised, frame.reference());
        }
        perFrame.push_back(entry);
        bar.update(double(i + 1) / double(frames.size()));
    }
    const std::size_t done = perFrame.size();
    const bool interrupted = done < frames.size();
    const nlohmann::json summary = {{"input", in.string()},
                                    {"model", denoiser.model().source()},
                                    {"precision", precisionName(denoiser.model().precision())},  // auto resolved
                                    {"frames", done},
                                    {"input_frames", frames.size()},
                                    {"interrupted", interrupted},
                                    {"milliseconds_per_frame", done > 0 ? totalSeconds * 1e3 / double(done) : 0.0},
                                    {"per_frame", perFrame}};
    // A run stopped before its first frame leaves nothing (`folder` goes if this run made it).
    if (done > 0)
        writeAtomically((out / "denoise_summary.json").string(), [&](const std::string& temporary) {
            std::ofstream file(temporary);
            file << summary.dump(2) << "\n";
            if (!file) throw Error("cannot write " + (out / "denoise_summary.json").string());
        });
    if (interrupted) return reportInterrupted("denoise", (long long)done, (long long)frames.size(), out.string());
    bar.finish(std::to_string(frames.size()) + " frames, " +
               std::to_string(int(totalSeconds * 1e3 / double(frames.size()))) + " ms per frame -> " + out.string());
    return 0;
}

}  // namespace affinity::cli
