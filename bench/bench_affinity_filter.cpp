// The affinity filter at 1920x1080 with F = 8 features: one spatial 5x5 pass per dilation
// (the three passes of a K = 3 model use dilations 1, 2, 4), the last pass with its temporal
// taps, and the bilinear warp of the history. Reports ms per pass (wall) and CPU ms per pass,
// which stays meaningful when other processes compete for the cores; compare numbers from
// the same run. Arguments: dilation and thread count.
#include <benchmark/benchmark.h>
#include <omp.h>

#include <ctime>
#include <random>
#include <vector>

#include "kernels/affinity_filter.h"
#include "kernels/bilinear_warp.h"

namespace affinity {
namespace {

constexpr int kHeight = 1080, kWidth = 1920, kFeatures = 8, kTapSize = 5;

double cpuSeconds() {
    timespec t{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

FeatureMap randomMap(int channels, float low, float high, std::mt19937& rng) {
    FeatureMap map(kHeight, kWidth, channels);
    std::uniform_real_distribution<float> uniform(low, high);
    for (std::size_t i = 0; i < map.size(); ++i) map.data()[i] = uniform(rng);
    return map;
}

struct Inputs {
    std::mt19937 rng{42};
    FeatureMap radiance = randomMap(3, 0.0f, 4.0f, rng);
    FeatureMap features = randomMap(kFeatures, -1.0f, 1.0f, rng);
    FeatureMap bandwidth = randomMap(1, -2.0f, 2.0f, rng);
    FeatureMap centre = randomMap(1, 0.0f, 1.0f, rng);
    FeatureMap temporalBandwidth = randomMap(1, -2.0f, 2.0f, rng);
    FeatureMap warpedOutput = randomMap(3, 0.0f, 4.0f, rng);
    FeatureMap warpedFeatures = randomMap(kFeatures, -1.0f, 1.0f, rng);
    FeatureMap warpedValid = randomMap(1, 0.0f, 1.0f, rng);
    std::vector<float> motion;
    FeatureMap output;

    Inputs() {
        std::uniform_real_distribution<float> uniform(-8.0f, 8.0f);
        motion.resize(std::size_t(kHeight) * kWidth * 2);
        for (float& m : motion) m = uniform(rng);
    }
    KernelParams kernel() const { return {&features, &bandwidth, &centre}; }
};

Inputs& inputs() {
    static Inputs shared;
    return shared;
}

// Runs `pass` per iteration and adds the CPU time per pass as a counter.
template <typename Pass>
void timePasses(benchmark::State& state, int threads, Pass pass) {
    const int before = omp_get_max_threads();
    omp_set_num_threads(threads);
    pass();  // warm-up: allocations and first-touch of the output
    const double cpu0 = cpuSeconds();
    for (auto _ : state) {
        pass();
        benchmark::ClobberMemory();
    }
    const double cpu = cpuSeconds() - cpu0;
    omp_set_num_threads(before);
    state.counters["cpu_ms_per_pass"] = 1e3 * cpu / double(state.iterations());
    state.counters["Mpixel_per_s"] =
        benchmark::Counter(double(kHeight) * kWidth * double(state.iterations()) * 1e-6, benchmark::Counter::kIsRate);
}

void spatialPass(benchmark::State& state) {
    Inputs& in = inputs();
    const int dilation = int(state.range(0));
    timePasses(state, int(state.range(1)),
               [&] { affinityFilter(in.radiance, in.kernel(), kTapSize, dilation, in.output); });
}

void temporalPass(benchmark::State& state) {
    Inputs& in = inputs();
    const int dilation = int(state.range(0));
    timePasses(state, int(state.range(1)), [&] {
        affinityFilterTemporal(in.radiance, in.kernel(), kTapSize, dilation, in.temporalBandwidth, in.warpedOutput,
                               in.warpedFeatures, in.warpedValid, in.output);
    });
}

void warpFeatures(benchmark::State& state) {
    Inputs& in = inputs();
    FeatureMap warped;
    timePasses(state, int(state.range(0)), [&] { warpBilinear(in.features, in.motion.data(), warped); });
}

BENCHMARK(spatialPass)
    ->ArgNames({"dilation", "threads"})
    ->ArgsProduct({{1, 2, 4}, {1, 2}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(temporalPass)
    ->ArgNames({"dilation", "threads"})
    ->ArgsProduct({{4}, {1, 2}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(warpFeatures)->ArgNames({"threads"})->ArgsProduct({{1, 2}})->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace affinity

BENCHMARK_MAIN();
