// `affinity render`: renders a scene's frames into a sequence folder of per-sample EXR files,
// with the scene description and a summary (timings, rays per second, noisy-input error).
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "affinity/atomic_file.h"
#include "affinity/error.h"
#include "affinity/frame_io.h"
#include "affinity/image_io.h"
#include "affinity/metrics.h"
#include "arguments.h"
#include "commands.h"
#include "progress_bar.h"
#include "render/scene_file.h"
#include "render/scene_library.h"
#include "render/sequence_renderer.h"

namespace affinity::cli {

namespace fs = std::filesystem;

namespace {

void writeText(const fs::path& path, const std::string& text) {
    writeAtomically(path.string(), [&](const std::string& temporary) {
        std::ofstream out(temporary);
        out << text;
        if (!out) throw Error("cannot write " + path.string());
    });
}

ExrCompression parseCompression(const std::string& name) {
    if (name == "none") return ExrCompression::None;
    if (name == "zip") return ExrCompression::Zip;
    if (name == "piz") return ExrCompression::Piz;
    throw Error("option --compression must be none, zip or piz, got '" + name + "'");
}

// Whether `name` is one of the names `render` gives a frame's files: frame_NNNN.exr,
// noisy_NNNN.png, reference_NNNN.png, spelt exactly as it writes them (as listFrameFiles reads
// frame files), so that a look-alike such as frame_1.exr or frame_0001.exr.bak is not one.
bool isRenderedFrameFile(const std::string& name) {
    static constexpr std::pair<std::string_view, std::string_view> kPatterns[] = {
        {"frame_", ".exr"}, {"noisy_", ".png"}, {"reference_", ".png"}};
    for (const auto& [prefix, suffix] : kPatterns) {
        if (name.size() <= prefix.size() + suffix.size() || !name.starts_with(prefix) || !name.ends_with(suffix))
            continue;
        const std::string digits = name.substr(prefix.size(), name.size() - prefix.size() - suffix.size());
        if (digits.size() < 4 || digits.size() > 7 || digits.find_first_not_of("0123456789") != std::string::npos)
            continue;
        char expected[64];
        std::snprintf(expected, sizeof expected, "%.*s%04d%.*s", int(prefix.size()), prefix.data(),
                      std::stoi(digits), int(suffix.size()), suffix.data());
        if (name == expected) return true;
    }
    return false;
}

// --force: the earlier sequence in `out` goes as a whole before the new one is written, so that
// the folder never holds frames of two runs (a shorter new run would otherwise leave the old
// run's later frames after its own, and `denoise` would take them as one sequence; a new run
// that fails part way would leave old frames after its last one). Only files `render` itself
// writes are removed; anything else in the folder stays.
void removeEarlierSequence(const fs::path& out) {
    std::vector<fs::path> earlier;
    for (const fs::directory_entry& entry : fs::directory_iterator(out)) {
        const std::string name = entry.path().filename().string();
        if (entry.is_directory()) continue;
        if (isRenderedFrameFile(name) || name == "render_summary.json" || name == "scene.json")
            earlier.push_back(entry.path());
    }
    for (const fs::path& path : earlier) {
        std::error_code error;
        if (!fs::remove(path, error) && error)
            throw Error("cannot remove " + path.string() + " of the earlier sequence: " + error.message());
    }
}

}  // namespace

int renderCommand(const std::vector<std::string>& args) {
    const Arguments a(args,
                      {"--scene", "--frames", "--spp", "--size", "--reference-spp", "--seed", "--out",
                       "--first-frame", "--compression", "--feature-convention"},
                      {"--force", "--previews"});
    render::RenderSettings settings;
    a.size("--size", settings.width, settings.height);
    settings.spp = a.integer("--spp", 4, 1, SampleFrame::kMaxSpp);
    settings.referenceSpp = a.integer("--reference-spp", 1024, 0, 1 << 20);
    settings.seed = a.unsignedInteger("--seed", 0);
    settings.featureConvention = render::parseFeatureConvention(a.text("--feature-convention", "renderer"));
    const int frames = a.integer("--frames", 8, 1, 100000);
    const int firstFrame = a.integer("--first-frame", 0, 0, 1000000);
    const ExrCompression compression = parseCompression(a.text("--compression", "piz"));
    const fs::path out = a.text("--out");
    const render::Scene scene = render::resolveScene(a.text("--scene"));

    // Never overwrite a sequence unless asked to.
    if (fs::exists(out) && !fs::is_directory(out)) throw Error("output " + out.string() + " exists and is not a folder");
    if (fs::is_directory(out) && !listFrameFiles(out.string()).empty() && !a.flag("--force"))
        throw Error("output folder " + out.string() + " already holds frames; pass --force to overwrite them");
    fs::create_directories(out);
    if (a.flag("--force")) removeEarlierSequence(out);
    writeText(out / "scene.json", render::sceneToJson(scene));

    render::SequenceRenderer renderer(scene, settings);
    nlohmann::json perFrame = nlohmann::json::array();
    double totalSeconds = 0.0;
    for (int i = 0; i < frames; ++i) {
        const int frameIndex = firstFrame + i;
        ProgressBar bar("frame " + std::to_string(i + 1) + "/" + std::to_string(frames));
        const auto start = std::chrono::steady_clock::now();
        const std::uint64_t raysBefore = renderer.raysCast();
        SampleFrame frame = renderer.render(frameIndex, [&](double f) { bar.update(f); });
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        const double rays = double(renderer.raysCast() - raysBefore);
        totalSeconds += seconds;

        writeFrame((out / frameFileName(frameIndex)).string(), frame, compression);
        nlohmann::json entry = {{"frame", frameIndex}, {"seconds", seconds}, {"rays_per_second", rays / seconds}};
        const std::vector<float> noisy = frame.meanRadiance();
        if (a.flag("--previews")) {
            char name[64];
            std::snprintf(name, sizeof name, "noisy_%04d.png", frameIndex);
            writeTonemappedPng((out / name).string(), frame.width(), frame.height(), noisy.data());
            if (frame.hasReference()) {
                std::snprintf(name, sizeof name, "reference_%04d.png", frameIndex);
                writeTonemappedPng((out / name).string(), frame.width(), frame.height(), frame.reference().data());
            }
        }
        if (frame.hasReference()) {
            const float* reference = frame.reference().data();
            entry["noisy_smape"] = smape(noisy.data(), reference, noisy.size());
            entry["noisy_relmse"] = relativeMse(noisy.data(), reference, noisy.size());
            entry["noisy_psnr"] = tonemappedPsnr(noisy.data(), reference, noisy.size());
        }
        perFrame.push_back(entry);
        bar.finish(std::to_string(int(rays / seconds / 1e6)) + " Mrays/s");
    }
    const nlohmann::json summary = {{"scene", scene.name},
                                    {"size", {settings.width, settings.height}},
                                    {"frames", frames},
                                    {"spp", settings.spp},
                                    {"reference_spp", settings.referenceSpp},
                                    {"seed", settings.seed},
                                    {"feature_convention", render::featureConventionName(settings.featureConvention)},
                                    {"seconds", totalSeconds},
                                    {"rays_per_second", double(renderer.raysCast()) / totalSeconds},
                                    {"per_frame", perFrame}};
    writeText(out / "render_summary.json", summary.dump(2) + "\n");
    std::printf("%s: %d frames of %dx%d at %d spp (reference %d spp) in %.1f s, %.1f Mrays/s -> %s\n",
                scene.name.c_str(), frames, settings.width, settings.height, settings.spp, settings.referenceSpp,
                totalSeconds, double(renderer.raysCast()) / totalSeconds / 1e6, out.string().c_str());
    return 0;
}

}  // namespace affinity::cli
