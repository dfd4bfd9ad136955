// How close the U-Net's hot loop gets to the machine: (a) the FP32 peak measured with an
// FMA microbenchmark (AVX2 and, where the CPU has it, AVX-512: the widest is the peak), (b)
// our 3x3 convolution at 1080p (its AVX2 and AVX-512 kernels, direct and in the Winograd form) as
// GFLOP/s and fraction of that peak,
// (c) the same convolutions through oneDNN as a yardstick, (d) the embedding MLP at 1080p.
// Run on a quiet machine with --benchmark_repetitions and compare numbers of the same run.
#include <benchmark/benchmark.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "affinity/features.h"
#include "network/embedding.h"
#include "fma_chains.h"
#include "kernels/simd8.h"
#include "network/unet_layers.h"

#if AFFINITY_BENCH_ONEDNN
#include <oneapi/dnnl/dnnl.hpp>
#endif

namespace affinity {
namespace {

constexpr int kHeight = 1080, kWidth = 1920;

// Wall and whole-process CPU seconds since construction. FLOP per CPU second is the kernel's
// speed per core while it actually ran, which stays meaningful when other processes
// compete for the cores; wall-clock rates do not.
struct Stopwatch {
    static double cpuNow() {
        timespec t{};
        clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
        return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
    }
    std::chrono::steady_clock::time_point wall0 = std::chrono::steady_clock::now();
    double cpu0 = cpuNow();
    double wall() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count(); }
    double cpu() const { return cpuNow() - cpu0; }
};

// Best rates seen per thread count (load from other processes only ever lowers them).
struct Peak {
    double wall = 0.0;    // FLOP per second
    double perCpu = 0.0;  // FLOP per CPU second
};

// ---- (a) FP32 peak ----------------------------------------------------------------------

// Lanes of the FMA loop used for the peak: 16 where the CPU has AVX-512 (on Zen 5 that doubles
// the peak; on Zen 4 it changes nothing), else 8.
int peakLanes() {
#if AFFINITY_BENCH_AVX512
    if (cpuHasAvx512()) return 16;
#endif
    return 8;
}

float fmaChains(int lanes, long long steps) {
#if AFFINITY_BENCH_AVX512
    if (lanes == 16) return fmaChainsAvx512(steps);
#endif
    return fmaChains<Float8>(steps);
}

// One parallel run of `steps` per thread on `threads` threads with `lanes`-wide vectors.
double flopPerStep(int lanes) { return kFmaChains * lanes * 2.0; }

Peak runFmaChains(int threads, int lanes, long long steps) {
    float sink = 0.0f;
    const Stopwatch watch;
#pragma omp parallel num_threads(threads) reduction(+ : sink)
    sink += fmaChains(lanes, steps);
    const double wall = watch.wall(), cpu = watch.cpu();
    benchmark::DoNotOptimize(sink);
    const double flop = threads * double(steps) * flopPerStep(lanes);
    return {flop / wall, flop / cpu};
}

std::map<int, Peak>& bestPeak() {
    static std::map<int, Peak> peaks;
    return peaks;
}

void updatePeak(int threads, const Peak& measured) {
    Peak& peak = bestPeak()[threads];
    peak.wall = std::max(peak.wall, measured.wall);
    peak.perCpu = std::max(peak.perCpu, measured.perCpu);
}

const Peak& peakFor(int threads) {
    if (bestPeak()[threads].wall == 0.0)
        for (int i = 0; i < 5; ++i) updatePeak(threads, runFmaChains(threads, peakLanes(), 1 << 22));
    return bestPeak()[threads];
}

// The peak of `lanes`-wide FMAs; the widest the CPU has is the peak every fraction refers to.
void fmaPeak(benchmark::State& state, int lanes) {
    const int threads = int(state.range(0));
    constexpr long long kSteps = 1 << 23;
    Peak best;
    for (auto _ : state) {
        const Peak run = runFmaChains(threads, lanes, kSteps);
        best.wall = std::max(best.wall, run.wall);
        best.perCpu = std::max(best.perCpu, run.perCpu);
    }
    if (lanes == peakLanes()) updatePeak(threads, best);
    state.counters["FLOPS"] = benchmark::Counter(
        threads * double(kSteps) * flopPerStep(lanes) * double(state.iterations()), benchmark::Counter::kIsRate);
    state.counters["best_FLOPS"] = best.wall;
    state.counters["FLOP_per_cpu_s"] = best.perCpu;
}

// ---- shared inputs ----------------------------------------------------------------------

// A fast deterministic generator: the 1080p inputs hold up to 130 M values.
struct Random {
    std::uint64_t state;
    float uniform(float lo, float hi) {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return lo + (hi - lo) * float(state >> 40) * (1.0f / 16777216.0f);
    }
};

struct ConvCase {
    FeatureMap input;
    std::vector<float> weight, bias;  // torch layout
};

const ConvCase& convCase(int in, int out) {
    static std::map<std::pair<int, int>, std::unique_ptr<ConvCase>> cases;
    auto& entry = cases[{in, out}];
    if (!entry) {
        entry = std::make_unique<ConvCase>();
        Random random{std::uint64_t(in * 1000 + out)};
        entry->input.resize(kHeight, kWidth, in);
        for (std::size_t i = 0; i < entry->input.size(); ++i) entry->input.data()[i] = random.uniform(-1.0f, 1.0f);
        const float scale = 1.0f / std::sqrt(float(in * 9));
        entry->weight.resize(std::size_t(out) * in * 9);
        for (float& w : entry->weight) w = random.uniform(-scale, scale);
        entry->bias.resize(std::size_t(out));
        for (float& b : entry->bias) b = random.uniform(-0.1f, 0.1f);
    }
    return *entry;
}

double convFlop(int in, int out) { return 2.0 * kHeight * kWidth * in * out * 9; }

// Sets the OpenMP team size for one benchmark and restores it afterwards.
struct ThreadScope {
    int saved = omp_get_max_threads();
    explicit ThreadScope(int threads) { omp_set_num_threads(threads); }
    ~ThreadScope() { omp_set_num_threads(saved); }
};

// Counters of a convolution benchmark whose timed loop took `watch`.
void reportConv(benchmark::State& state, const Stopwatch& watch, int in, int out, int threads) {
    const double flop = convFlop(in, out) * double(state.iterations());
    const Peak& peak = peakFor(threads);
    const double wallRate = flop / watch.wall(), cpuRate = flop / watch.cpu();
    state.counters["FLOPS"] = wallRate;
    state.counters["peak_frac"] = wallRate / peak.wall;
    // Per CPU second against the FMA loop per CPU second: the fraction of peak the kernel
    // reaches while it runs, robust to other processes taking the cores (OpenMP threads
    // that wait at the end of a layer spin and count as busy, so this errs low).
    state.counters["FLOP_per_cpu_s"] = cpuRate;
    state.counters["cpu_peak_frac"] = cpuRate / peak.perCpu;
}

// ---- (b) our convolution ----------------------------------------------------------------

// `form` Winograd: winograd_conv.h (FLOPS still count the direct form's 9 taps, so the rate shows
// the time saved).
void ourConv(benchmark::State& state, ConvIsa isa, ConvForm form) {
    const int in = int(state.range(0)), out = int(state.range(1)), threads = int(state.range(2));
    const ConvCase& c = convCase(in, out);
    peakFor(threads);
    const Conv2d conv(c.weight.data(), c.bias.data(), out, in, 3, isa, 0, form);
    const ThreadScope scope(threads);
    FeatureMap output;
    conv.apply(c.input, Activation::LeakyRelu, output);  // allocate outside the timing
    const Stopwatch watch;
    for (auto _ : state) {
        conv.apply(c.input, Activation::LeakyRelu, output);
        benchmark::ClobberMemory();
    }
    reportConv(state, watch, in, out, threads);
}

// The decoder's form: concat(upsampled coarse level, skip) without materialising either,
// `in` channels split as coarse = in - in / 2 (read at half resolution) and skip = in / 2;
// `folded`: as the denoiser runs it (upsampled_conv.h, 4 coarse taps instead of 9; FLOPS
// still count the unfolded 9, so the rate shows the time saved).
void ourUpsampledConv(benchmark::State& state, bool folded) {
    const int in = int(state.range(0)), out = int(state.range(1)), threads = int(state.range(2));
    const int skipChannels = in / 2, coarseChannels = in - skipChannels;
    const ConvCase& c = convCase(in, out);
    peakFor(threads);
    FeatureMap coarse((kHeight + 1) / 2, (kWidth + 1) / 2, coarseChannels), skip(kHeight, kWidth, skipChannels);
    for (FeatureMap* map : {&coarse, &skip}) std::copy(c.input.data(), c.input.data() + map->size(), map->data());
    const Conv2d conv(c.weight.data(), c.bias.data(), out, in, 3, defaultConvIsa(), folded ? coarseChannels : 0);
    const ThreadScope scope(threads);
    FeatureMap output;
    conv.applyUpsampled(coarse, skip, Activation::LeakyRelu, output);
    const Stopwatch watch;
    for (auto _ : state) {
        conv.applyUpsampled(coarse, skip, Activation::LeakyRelu, output);
        benchmark::ClobberMemory();
    }
    reportConv(state, watch, in, out, threads);
}

// ---- (c) oneDNN -------------------------------------------------------------------------

#if AFFINITY_BENCH_ONEDNN
// blockedActivations: let oneDNN also pick the activations' layout (its blocked nChw8c on
// AVX2), converting outside the timing: oneDNN at its best rather than on our layout.
// bf16: activations and weights in bfloat16 (accumulation and bias in FP32), what lower precision
// would buy where the CPU has AMX or AVX512-BF16; rel_diff_vs_ours then shows what it costs.
void oneDnnConv(benchmark::State& state, bool blockedActivations, bool bf16) {
    using namespace dnnl;
    using tag = memory::format_tag;
    using dt = memory::data_type;
    const int in = int(state.range(0)), out = int(state.range(1)), threads = int(state.range(2));
    const ConvCase& c = convCase(in, out);
    peakFor(threads);
    const ThreadScope scope(threads);

    const engine cpu(engine::kind::cpu, 0);
    stream queue(cpu);
    const memory::dims srcDims{1, in, kHeight, kWidth}, weightDims{out, in, 3, 3}, biasDims{out},
        dstDims{1, out, kHeight, kWidth}, strides{1, 1}, padding{1, 1};
    // NHWC activations like ours; the weights' layout is oneDNN's choice (tag::any).
    const tag activationTag = blockedActivations ? tag::any : tag::nhwc;
    const dt type = bf16 ? dt::bf16 : dt::f32;
    const memory::desc srcDesc(srcDims, type, activationTag), dstDesc(dstDims, type, activationTag),
        weightDesc(weightDims, type, tag::any), biasDesc(biasDims, dt::f32, tag::a);
    const convolution_forward::desc opDesc(prop_kind::forward_inference, algorithm::convolution_direct, srcDesc,
                                           weightDesc, biasDesc, dstDesc, strides, padding, padding);
    // The same fused leaky ReLU as ours.
    post_ops ops;
    ops.append_eltwise(1.0f, algorithm::eltwise_relu, 0.01f, 0.0f);
    primitive_attr attributes;
    attributes.set_post_ops(ops);
    convolution_forward::primitive_desc primitiveDesc;
    try {
        primitiveDesc = convolution_forward::primitive_desc(opDesc, attributes, cpu);
    } catch (const dnnl::error& e) {  // no bf16 convolution for this CPU
        state.SkipWithError(e.what());
        return;
    }
    state.SetLabel(primitiveDesc.impl_info_str());

    memory userSrc({srcDims, dt::f32, tag::nhwc}, cpu, const_cast<float*>(c.input.data()));
    memory src(primitiveDesc.src_desc(), cpu);
    reorder(userSrc, src).execute(queue, userSrc, src);
    memory torchWeights({weightDims, dt::f32, tag::oihw}, cpu, const_cast<float*>(c.weight.data()));
    memory weights(primitiveDesc.weights_desc(), cpu);
    reorder(torchWeights, weights).execute(queue, torchWeights, weights);
    memory bias(biasDesc, cpu, const_cast<float*>(c.bias.data()));
    memory dst(primitiveDesc.dst_desc(), cpu);
    const convolution_forward conv(primitiveDesc);
    const std::unordered_map<int, memory> args{
        {DNNL_ARG_SRC, src}, {DNNL_ARG_WEIGHTS, weights}, {DNNL_ARG_BIAS, bias}, {DNNL_ARG_DST, dst}};
    conv.execute(queue, args);  // first run builds the kernel
    queue.wait();

    // Same function as ours? Largest difference relative to the largest output.
    FeatureMap ours;
    Conv2d(c.weight.data(), c.bias.data(), out, in, 3).apply(c.input, Activation::LeakyRelu, ours);
    memory userDst({dstDims, dt::f32, tag::nhwc}, cpu);
    reorder(dst, userDst).execute(queue, dst, userDst);
    queue.wait();
    const float* theirs = static_cast<const float*>(userDst.get_data_handle());
    double maxDiff = 0.0, maxValue = 0.0;
    for (std::size_t i = 0; i < ours.size(); ++i) {
        maxDiff = std::max(maxDiff, double(std::abs(ours.data()[i] - theirs[i])));
        maxValue = std::max(maxValue, double(std::abs(ours.data()[i])));
    }
    state.counters["rel_diff_vs_ours"] = maxDiff / maxValue;

    const Stopwatch watch;
    for (auto _ : state) {
        conv.execute(queue, args);
        queue.wait();
    }
    reportConv(state, watch, in, out, threads);
}
#endif

// ---- (d) embedding ----------------------------------------------------------------------

constexpr int kEmbeddingSpp = 4;
const int kEmbeddingWidths[] = {kFeatureCount, 32, 32, 32};

const std::vector<float>& embeddingSamples() {
    static const std::vector<float> samples = [] {
        std::vector<float> s(std::size_t(kHeight) * kWidth * kEmbeddingSpp * kFeatureCount);
        Random random{7};
        for (std::size_t i = 0; i < s.size(); i += kFeatureCount) {
            float* f = s.data() + i;
            for (int k = 0; k < kFeatureCount; ++k) f[k] = random.uniform(0.0f, 1.0f);
            for (int k = 0; k < 6; ++k) f[k] = std::exp(random.uniform(-6.0f, 6.0f));
            f[channel::kDepth] = random.uniform(0.0f, 50.0f);
        }
        return s;
    }();
    return samples;
}

void embedding(benchmark::State& state) {
    const int threads = int(state.range(0));
    Random random{11};
    std::vector<DenseLayer> layers;
    for (int i = 0; i + 1 < int(std::size(kEmbeddingWidths)); ++i) {
        DenseLayer layer;
        layer.in = kEmbeddingWidths[i];
        layer.out = kEmbeddingWidths[i + 1];
        const float scale = 1.0f / std::sqrt(float(layer.in));
        layer.weight.resize(std::size_t(layer.in) * layer.out);
        for (float& w : layer.weight) w = random.uniform(-scale, scale);
        layer.bias.assign(std::size_t(layer.out), 0.01f);
        layers.push_back(std::move(layer));
    }
    const Embedding net(std::move(layers));
    const std::vector<float>& samples = embeddingSamples();
    const ThreadScope scope(threads);
    FeatureMap output;
    net.apply(samples.data(), kHeight, kWidth, kEmbeddingSpp, 0.04f, output);
    const Stopwatch watch;
    for (auto _ : state) {
        benchmark::DoNotOptimize(net.apply(samples.data(), kHeight, kWidth, kEmbeddingSpp, 0.04f, output));
        benchmark::ClobberMemory();
    }
    // FLOP of the definition: every layer for every sample.
    double perSample = 0.0;
    for (int i = 0; i + 1 < int(std::size(kEmbeddingWidths)); ++i)
        perSample += 2.0 * kEmbeddingWidths[i] * kEmbeddingWidths[i + 1];
    const double count = double(kHeight) * kWidth * kEmbeddingSpp * double(state.iterations());
    const double wall = watch.wall(), cpu = watch.cpu();
    state.counters["samples_per_s"] = count / wall;
    state.counters["model_FLOPS"] = count * perSample / wall;
    state.counters["model_FLOP_per_cpu_s"] = count * perSample / cpu;
}

void registerAll() {
    const int all = omp_get_max_threads();
    std::vector<int> threadCounts{1};
    if (all > 1) threadCounts.push_back(all);

    for (const int lanes : {8, 16}) {
        if (lanes > peakLanes()) continue;
        auto* peak = benchmark::RegisterBenchmark(lanes == 8 ? "FmaPeak/avx2" : "FmaPeak/avx512", fmaPeak, lanes);
        for (int t : threadCounts) peak->Arg(t);
        peak->ArgNames({"threads"})->UseRealTime()->Unit(benchmark::kMillisecond);
    }

    // {64, 24}: the small model's first layer (its embedding and the warped history).
    const std::vector<std::pair<int, int>> shapes{{32, 32}, {16, 16}, {24, 32}, {64, 64}, {40, 16}, {56, 24}, {64, 24}};
    auto addShapes = [&](benchmark::internal::Benchmark* b) {
        for (const auto& [in, out] : shapes) b->Args({in, out, all});
        if (all > 1) b->Args({32, 32, 1});  // per-core efficiency
        b->ArgNames({"in", "out", "threads"})->UseRealTime()->Unit(benchmark::kMillisecond);
    };
    addShapes(benchmark::RegisterBenchmark("Conv3x3/ours_avx2", ourConv, ConvIsa::Avx2, ConvForm::Direct));
    if (cpuHasAvx512())
        addShapes(benchmark::RegisterBenchmark("Conv3x3/ours_avx512", ourConv, ConvIsa::Avx512, ConvForm::Direct));
    addShapes(benchmark::RegisterBenchmark("Conv3x3/ours_winograd_avx2", ourConv, ConvIsa::Avx2, ConvForm::Winograd));
    if (cpuHasAvx512())
        addShapes(
            benchmark::RegisterBenchmark("Conv3x3/ours_winograd_avx512", ourConv, ConvIsa::Avx512, ConvForm::Winograd));
    for (const bool folded : {false, true}) {
        auto* upsampled = benchmark::RegisterBenchmark(
            folded ? "Conv3x3Upsampled/ours_folded" : "Conv3x3Upsampled/ours", ourUpsampledConv, folded);
        for (const auto& [in, out] : std::vector<std::pair<int, int>>{{40, 16}, {56, 24}, {32, 32}})
            upsampled->Args({in, out, all});
        upsampled->ArgNames({"in", "out", "threads"})->UseRealTime()->Unit(benchmark::kMillisecond);
    }
#if AFFINITY_BENCH_ONEDNN
    addShapes(benchmark::RegisterBenchmark("Conv3x3/onednn_nhwc", oneDnnConv, false, false));
    addShapes(benchmark::RegisterBenchmark("Conv3x3/onednn_blocked", oneDnnConv, true, false));
    addShapes(benchmark::RegisterBenchmark("Conv3x3/onednn_bf16_nhwc", oneDnnConv, false, true));
    addShapes(benchmark::RegisterBenchmark("Conv3x3/onednn_bf16_blocked", oneDnnConv, true, true));
#endif

    auto* embed = benchmark::RegisterBenchmark("Embedding1080p_4spp_18-32-32-32", embedding);
    for (int t : threadCounts) embed->Arg(t);
    embed->ArgNames({"threads"})->UseRealTime()->Unit(benchmark::kMillisecond);
}

}  // namespace
}  // namespace affinity

int main(int argc, char** argv) {
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
    affinity::registerAll();
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
