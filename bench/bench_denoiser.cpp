// The whole denoiser on one model at one frame size: milliseconds per frame (median over the
// timed frames, the first frame excluded as it has no history), the median of every pipeline
// stage, CPU seconds per frame, the convolution FLOP rate, the process's peak memory (input
// frame included) and the denoiser's own buffers (DenoiseReport::bufferBytes). One model per
// process, so that peak memory is that model's.
//
//   bench_denoiser [--model FILE.affw] [--size 1920x1080] [--spp 4] [--frames 6] [--threads N]
//                  [--stream 1 | --lend 1] [--precision fp32|bf16|auto]
//
// --stream 1 feeds each frame one sample at a time (Denoiser::addSamples, as the Blender
// extension does), so only one sample's features are held: the input is then 1/spp the size.
// --lend 1 makes each frame's samples in a buffer the denoiser lends (Denoiser::sampleBands, as
// `affinity denoise` reads frame files), whose memory serves the later stages once embedded.
//
// --precision bf16 takes the Winograd convolutions' and the embedding's products in bfloat16
// (affinity/precision.h; CPUs with AVX512-BF16). The default here is fp32, not the library's
// auto, so that a row measures the same arithmetic on every machine (bench_denoiser.sh asks for
// bf16 rows by name).
//
// Prints one JSON object. Content of the frame does not matter for speed: plausible random
// features with a small motion everywhere.
#include <omp.h>
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "affinity/denoiser.h"
#include "affinity/error.h"

namespace affinity {
namespace {

struct Options {
    std::string model;  // empty: the built-in model
    int width = 1920, height = 1080, spp = 4, frames = 6, threads = 0;
    bool stream = false, lend = false;
    Precision precision = Precision::Float32;  // not Auto: see above
};

Options parse(int argc, char** argv) {
    Options options;
    for (int i = 1; i < argc; ++i) {
        const std::string flag = argv[i];
        if (i + 1 >= argc) throw Error("bench_denoiser: " + flag + " needs a value");
        const std::string value = argv[++i];
        if (flag == "--model")
            options.model = value;
        else if (flag == "--size") {
            if (std::sscanf(value.c_str(), "%dx%d", &options.width, &options.height) != 2)
                throw Error("bench_denoiser: --size must be WIDTHxHEIGHT, got " + value);
        } else if (flag == "--spp")
            options.spp = std::stoi(value);
        else if (flag == "--frames")
            options.frames = std::max(2, std::stoi(value));
        else if (flag == "--threads")
            options.threads = std::stoi(value);
        else if (flag == "--stream")
            options.stream = value == "1";
        else if (flag == "--lend")
            options.lend = value == "1";
        else if (flag == "--precision")
            options.precision = precisionFromName(value);
        else
            throw Error("bench_denoiser: unknown option " + flag);
    }
    return options;
}

// Plausible random features for spp samples per pixel, [y][x][s][feature].
void fillRandomSamples(float* samples, int width, int height, int spp, std::uint32_t seed) {
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y) {
        std::mt19937 rng(seed * 100003u + std::uint32_t(y));
        std::uniform_real_distribution<float> u(0.0f, 1.0f);
        float* f = samples + std::size_t(y) * std::size_t(width) * std::size_t(spp) * kFeatureCount;
        for (int i = 0; i < width * spp; ++i, f += kFeatureCount) {
            for (int c = 0; c < 9; ++c) f[c] = u(rng);
            const float nx = u(rng) - 0.5f, ny = u(rng) - 0.5f, n = std::sqrt(nx * nx + ny * ny + 1.0f);
            f[9] = nx / n, f[10] = ny / n, f[11] = 1.0f / n;
            f[12] = 2.0f + 3.0f * u(rng);
            f[13] = u(rng);
            for (int c = 14; c < kFeatureCount; ++c) f[c] = u(rng) < 0.2f ? 1.0f : 0.0f;
        }
    }
}

// A frame of `spp` random samples, or with none (spp 0) for a denoiser-lent buffer; a small
// motion everywhere.
SampleFrame randomFrame(int width, int height, int spp, std::uint32_t seed) {
    SampleFrame frame =
        spp > 0 ? SampleFrame(width, height, spp, false) : SampleFrame::withoutSamples(width, height, 1, false);
    frame.info.worldToCamera = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -5, 0, 0, 0, 1};
    if (spp > 0) fillRandomSamples(frame.samples().data(), width, height, spp, seed);
    for (std::size_t i = 0; i < frame.pixelCount(); ++i) {
        frame.motion()[2 * i] = 0.5f;
        frame.motion()[2 * i + 1] = -0.25f;
        frame.valid()[i] = 1.0f;
    }
    return frame;
}

double cpuSeconds() {
    timespec t{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

double median(std::vector<double> values) {
    std::sort(values.begin(), values.end());
    const std::size_t n = values.size();
    return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

int run(const Options& options) {
    if (options.threads > 0) omp_set_num_threads(options.threads);
    Model model =
        options.model.empty() ? Model::builtIn(options.precision) : Model::fromFile(options.model, options.precision);
    // Streaming holds one sample and feeds it spp times (the values do not matter for speed); a
    // lent frame's samples are made in the denoiser's buffer before each frame, untimed.
    const SampleFrame frame = randomFrame(options.width, options.height,
                                          options.stream ? 1
                                          : options.lend ? 0
                                                         : options.spp,
                                          1);
    Denoiser denoiser(model);
    std::vector<double> wall, cpu;
    std::map<std::string, std::vector<double>> stages;
    std::vector<std::string> stageOrder;
    std::size_t bufferBytes = 0;  // the denoiser's own buffers after the last frame
    for (int i = 0; i < options.frames; ++i) {
        DenoiseReport report;
        if (options.lend)
            for (const SampleBand& band : denoiser.sampleBands(options.width, options.height, options.spp))
                fillRandomSamples(band.samples, options.width, band.rows, options.spp,
                                  1u + std::uint32_t(band.firstRow));
        const double cpuStart = cpuSeconds();
        const auto start = std::chrono::steady_clock::now();
        std::vector<float> output;
        if (options.stream) {
            for (int s = 0; s < options.spp; ++s)
                denoiser.addSamples(frame.width(), frame.height(), 1, frame.samples().data());
            output = denoiser.finishFrame(frame.motion().data(), frame.valid().data(), frame.info, &report);
        } else if (options.lend) {
            output = denoiser.finishFrame(frame.motion().data(), frame.valid().data(), frame.info, &report);
        } else {
            output = denoiser.denoise(frame, &report);
        }
        const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
        bufferBytes = report.bufferBytes;
        if (i == 0) continue;  // no history yet: not the steady state
        wall.push_back(ms);
        cpu.push_back(cpuSeconds() - cpuStart);
        for (const auto& [stage, stageMs] : report.stageMilliseconds) {
            if (stages.find(stage) == stages.end()) stageOrder.push_back(stage);
            stages[stage].push_back(stageMs);
        }
    }
    const double inputBytes =
        double(options.width) * options.height * (options.stream ? 1 : options.spp) * kFeatureCount * sizeof(float);
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    const double pixels = double(options.width) * options.height;
    std::printf(
        "{\"model\": \"%s\", \"parameters\": %lld, \"kflop_per_pixel\": %.1f, \"size\": \"%dx%d\", "
        "\"spp\": %d, \"threads\": %d, \"timed_frames\": %zu, \"ms_per_frame\": %.1f, "
        "\"ms_per_megapixel\": %.1f, \"cpu_seconds_per_frame\": %.3f, \"gflops_per_cpu_second\": %.1f, "
        "\"peak_rss_mb\": %.0f, \"buffer_mb\": %.0f, \"input_frame_mb\": %.0f, \"streamed\": %s, \"lent\": %s, "
        "\"precision\": \"%s\", \"stage_ms\": {",
        model.source().c_str(), static_cast<long long>(model.parameterCount()),
        model.flopsPerPixel(options.spp) / 1000.0, options.width, options.height, options.spp, omp_get_max_threads(),
        wall.size(), median(wall), median(wall) / (pixels / 1e6), median(cpu),
        model.flopsPerPixel(options.spp) * pixels / median(cpu) / 1e9, double(usage.ru_maxrss) / 1024.0,
        double(bufferBytes) / (1024.0 * 1024.0), inputBytes / (1024.0 * 1024.0), options.stream ? "true" : "false",
        options.lend ? "true" : "false", precisionName(model.precision()));
    for (std::size_t i = 0; i < stageOrder.size(); ++i)
        std::printf("%s\"%s\": %.1f", i ? ", " : "", stageOrder[i].c_str(), median(stages[stageOrder[i]]));
    std::printf("}}\n");
    return 0;
}

}  // namespace
}  // namespace affinity

int main(int argc, char** argv) {
    try {
        return affinity::run(affinity::parse(argc, argv));
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s\n", e.what());
        return 1;
    }
}
