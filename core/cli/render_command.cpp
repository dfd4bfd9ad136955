// `affinity render`: renders a scene's frames into a sequence folder of per-sample EXR files,
// with the scene description and a summary (timings, rays per second, noisy-input error).
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <new>
#include <optional>
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
#include "interrupt.h"
#include "output_folder.h"
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
        std::snprintf(expected, sizeof expected, "%.*s%04d%.*s", int(prefix.size()), prefix.data(), std::stoi(digits),
                      int(suffix.size()), suffix.data());
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

std::string formatBytes(double bytes) {
    char text[32];
    if (bytes >= double(1ull << 30))
        std::snprintf(text, sizeof text, "%.1f GiB", bytes / double(1ull << 30));
    else
        std::snprintf(text, sizeof text, "%.0f MiB", bytes / double(1ull << 20));
    return text;
}

// The number after `key` in a "key value" file such as /proc/meminfo, if there is one.
std::optional<double> readField(const char* path, const std::string& key) {
    std::ifstream in(path);
    for (std::string name; in >> name;) {
        double value = 0.0;
        if (name == key) return in >> value ? std::optional<double>(value) : std::nullopt;
        in.ignore(1 << 12, '\n');
    }
    return std::nullopt;
}

// Memory a new allocation can still get, and where that figure comes from: MemAvailable, or a
// container's cgroup v2 limit where that is lower (then the limit, not the host's memory, ends
// the run), less what the cgroup uses other than page cache (reclaimed when needed). Where
// /proc/meminfo cannot be read, the physical memory as the only bound known; nothing where that
// is unknown too.
std::optional<std::pair<double, std::string>> availableMemory() {
    std::optional<std::pair<double, std::string>> available;
    if (const auto kib = readField("/proc/meminfo", "MemAvailable:"))
        available = {{*kib * 1024.0, "MemAvailable in /proc/meminfo"}};
    std::ifstream limitFile("/sys/fs/cgroup/memory.max"), currentFile("/sys/fs/cgroup/memory.current");
    double limit = 0.0, current = 0.0;
    if (limitFile >> limit && currentFile >> current) {  // "max" (no limit) does not read as a number
        const double cache = readField("/sys/fs/cgroup/memory.stat", "file").value_or(0.0);
        const double left = std::max(0.0, limit - std::max(0.0, current - cache));
        if (!available || left < available->first) available = {{left, "the cgroup's memory.max"}};
    }
    if (!available) {
        const long pages = ::sysconf(_SC_PHYS_PAGES), pageSize = ::sysconf(_SC_PAGE_SIZE);
        if (pages > 0 && pageSize > 0) available = {{double(pages) * double(pageSize), "the physical memory"}};
    }
    return available;
}

// A run holds one frame at a time (each is written before the next is rendered): its samples,
// motion, validity and reference, the mean radiance and previews made from it, OpenEXR's buffers
// while writing it, and the program with its scene. Refused before anything is written when
// that is more than the machine has, rather than failing on an allocation part way.
void checkMemory(const render::RenderSettings& settings, ExrCompression compression, bool previews) {
    const double pixels = double(settings.width) * double(settings.height);
    const bool withReference = settings.referenceSpp > 0;
    const double frame = pixels * double(settings.spp * kFeatureCount + 3 + (withReference ? 3 : 0)) * sizeof(float);
    const double writing =
        double(frameWriteBufferBytes(settings.width, settings.height, settings.spp, withReference, compression));
    // Mean radiance (3 floats); a preview's 8-bit pixels, PNG filter rows and encoding.
    const double images = pixels * (3 * sizeof(float) + (previews ? 12.0 : 0.0));
    constexpr double kProgramAndScene = 64.0 * (1 << 20);
    const double needed = frame + writing + images + kProgramAndScene;
    const auto available = availableMemory();
    if (!available || needed <= available->first) return;
    throw Error("rendering " + std::to_string(settings.width) + "x" + std::to_string(settings.height) + " at " +
                std::to_string(settings.spp) + " spp needs about " + formatBytes(needed) + " of memory (" +
                formatBytes(frame) + " for a frame, " + formatBytes(writing) + " to write it), but " +
                formatBytes(available->first) + " is available (" + available->second +
                "): use a smaller --size or --spp");
}

}  // namespace

int renderCommand(const std::vector<std::string>& args) {
    const Arguments a(args,
                      {"--scene", "--frames", "--spp", "--size", "--reference-spp", "--seed", "--out", "--first-frame",
                       "--compression", "--feature-convention"},
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
    if (fs::exists(out) && !fs::is_directory(out))
        throw Error("output " + out.string() + " exists and is not a folder");
    if (fs::is_directory(out) && !listFrameFiles(out.string()).empty() && !a.flag("--force"))
        throw Error("output folder " + out.string() + " already holds frames; pass --force to overwrite them");
    // Every check before anything is written: a refused run leaves the folder as it was.
    render::SequenceRenderer renderer(scene, settings);
    checkMemory(settings, compression, a.flag("--previews"));

    // Before anything is written: a signal from here on leaves what was finished, nothing half-made.
    installInterruptHandlers();
    const OutputFolder folder(out);
    if (a.flag("--force")) removeEarlierSequence(out);
    // Until its first frame is written, a run that fails takes back its scene.json (and then
    // `folder` the folder, if it made it), so that no folder is left describing frames it lacks.
    bool wroteFrame = false;
    struct SceneFileUntilFirstFrame {
        fs::path path;
        const bool& wroteFrame;
        ~SceneFileUntilFirstFrame() {
            std::error_code ignored;
            if (!wroteFrame) fs::remove(path, ignored);
        }
    } sceneFile{out / "scene.json", wroteFrame};
    writeText(sceneFile.path, render::sceneToJson(scene));

    nlohmann::json perFrame = nlohmann::json::array();
    double totalSeconds = 0.0;
    for (int i = 0; i < frames && !interruptRequested(); ++i) {
        const int frameIndex = firstFrame + i;
        ProgressBar bar("frame " + std::to_string(i + 1) + "/" + std::to_string(frames));
        const auto start = std::chrono::steady_clock::now();
        const std::uint64_t raysBefore = renderer.raysCast();
        SampleFrame frame;
        try {
            frame = renderer.render(
                frameIndex, [&](double f) { bar.update(f); }, interruptRequested);
        } catch (const Interrupted&) {
            break;
        } catch (const std::bad_alloc&) {
            // checkMemory() estimates; what else runs on the machine may still take the rest.
            throw Error("out of memory rendering frame " + std::to_string(frameIndex) +
                        ": use a smaller --size or --spp");
        }
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        const double rays = double(renderer.raysCast() - raysBefore);
        totalSeconds += seconds;

        writeFrame((out / frameFileName(frameIndex)).string(), frame, compression);
        wroteFrame = true;
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
    const int done = int(perFrame.size());
    const nlohmann::json summary = {
        {"scene", scene.name},
        {"size", {settings.width, settings.height}},
        {"frames", done},
        {"requested_frames", frames},
        {"interrupted", done < frames},
        {"spp", settings.spp},
        {"reference_spp", settings.referenceSpp},
        {"seed", settings.seed},
        {"feature_convention", render::featureConventionName(settings.featureConvention)},
        {"seconds", totalSeconds},
        {"rays_per_second", totalSeconds > 0 ? double(renderer.raysCast()) / totalSeconds : 0.0},
        {"per_frame", perFrame}};
    if (done > 0) writeText(out / "render_summary.json", summary.dump(2) + "\n");
    if (done < frames) return reportInterrupted("render", done, frames, out.string());
    std::printf("%s: %d frames of %dx%d at %d spp (reference %d spp) in %.1f s, %.1f Mrays/s -> %s\n",
                scene.name.c_str(), frames, settings.width, settings.height, settings.spp, settings.referenceSpp,
                totalSeconds, double(renderer.raysCast()) / totalSeconds / 1e6, out.string().c_str());
    return 0;
}

}  // namespace affinity::cli
