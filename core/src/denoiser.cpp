// The per-frame pipeline of docs/MODEL.md: embedding -> warp and accumulate -> U-Net ->
// per-pixel kernel parameters -> dilated affinity kernels -> temporal kernel.
#include "affinity/denoiser.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "affinity/error.h"
#include "affinity_filter.h"
#include "feature_map_pool.h"
#include "network.h"

namespace affinity {
namespace {

float sigmoid(float x) { return 1.0f / (1.0f + std::exp(-x)); }

// 1 / mean depth of the samples that hit something (docs/MODEL.md section 1).
float depthScale(const SampleFrameView& frame) {
    double sum = 0.0;
    long long count = 0;
    const std::size_t values = frame.pixelCount() * std::size_t(frame.spp) * kFeatureCount;
    for (std::size_t i = channel::kDepth; i < values; i += kFeatureCount) {
        float depth = frame.samples[i];
        if (std::isfinite(depth) && depth > 0.0f) {
            sum += depth;
            ++count;
        }
    }
    return count > 0 ? float(double(count) / sum) : 0.0f;
}

// Per-pixel mean radiance with non-finite and negative values read as 0.
void noisyRadiance(const SampleFrameView& frame, FeatureMap& out) {
    out.resize(frame.height, frame.width, 3);
    const int spp = frame.spp;
    const float scale = 1.0f / float(spp);
#pragma omp parallel for schedule(static)
    for (int y = 0; y < frame.height; ++y) {
        for (int x = 0; x < frame.width; ++x) {
            float* o = out.pixel(y, x);
            o[0] = o[1] = o[2] = 0.0f;
            for (int s = 0; s < spp; ++s) {
                const float* f = frame.sample(x, y, s);
                for (int c = 0; c < 3; ++c) {
                    float d = f[channel::kDiffuse + c], sp = f[channel::kSpecular + c];
                    o[c] += (std::isfinite(d) && d > 0.0f ? d : 0.0f) + (std::isfinite(sp) && sp > 0.0f ? sp : 0.0f);
                }
            }
            for (int c = 0; c < 3; ++c) o[c] *= scale;
        }
    }
}

// warped = current wherever the history is not valid.
void keepWhereValid(FeatureMap& warped, const FeatureMap& current, const float* valid) {
    const int channels = current.channels();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < current.height(); ++y)
        for (int x = 0; x < current.width(); ++x)
            if (!(valid[std::size_t(y) * std::size_t(current.width()) + std::size_t(x)] > 0.5f)) {
                const float* from = current.pixel(y, x);
                std::copy(from, from + channels, warped.pixel(y, x));
            }
}

// history = (1 - lambda) current + lambda history, in place.
void blendInto(const FeatureMap& current, const FeatureMap& lambda, FeatureMap& history) {
    const int channels = current.channels();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < current.height(); ++y)
        for (int x = 0; x < current.width(); ++x) {
            const float l = lambda.pixel(y, x)[0];
            const float* c = current.pixel(y, x);
            float* h = history.pixel(y, x);
            for (int k = 0; k < channels; ++k) h[k] = (1.0f - l) * c[k] + l * h[k];
        }
}

// state = (1 - lambda) current + lambda history.
void blend(const FeatureMap& current, const FeatureMap& history, const FeatureMap& lambda, FeatureMap& out) {
    out.resize(current.height(), current.width(), current.channels());
    const int channels = current.channels();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < current.height(); ++y)
        for (int x = 0; x < current.width(); ++x) {
            const float l = lambda.pixel(y, x)[0];
            const float* c = current.pixel(y, x);
            const float* h = history.pixel(y, x);
            float* o = out.pixel(y, x);
            for (int k = 0; k < channels; ++k) o[k] = (1.0f - l) * c[k] + l * h[k];
        }
}

// Angle in degrees between two cameras' viewing directions, and the distance between them.
void cameraChange(const Matrix4& a, const Matrix4& b, double& degrees, double& distance) {
    // Row 2 of world-to-camera is the camera's +Z axis in world space; the position is
    // -R^T t.
    double dot = 0.0;
    for (int i = 0; i < 3; ++i) dot += double(a[8 + i]) * b[8 + i];
    degrees = std::acos(std::clamp(dot, -1.0, 1.0)) * 180.0 / 3.14159265358979;
    distance = 0.0;
    for (int i = 0; i < 3; ++i) {
        double pa = 0.0, pb = 0.0;
        for (int r = 0; r < 3; ++r) {
            pa -= double(a[r * 4 + i]) * a[r * 4 + 3];
            pb -= double(b[r * 4 + i]) * b[r * 4 + 3];
        }
        distance += (pa - pb) * (pa - pb);
    }
    distance = std::sqrt(distance);
}

// Appends the time since the previous mark to a report's stage list.
class StageClock {
public:
    explicit StageClock(DenoiseReport& report) : report_(report) {}
    void mark(const char* stage) {
        const auto now = std::chrono::steady_clock::now();
        report_.stageMilliseconds.emplace_back(stage, std::chrono::duration<double, std::milli>(now - last_).count());
        last_ = now;
    }

private:
    DenoiseReport& report_;
    std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

}  // namespace

struct Denoiser::State {
    Model model;
    DenoiserOptions options;
    bool hasHistory = false;
    int width = 0, height = 0;
    Matrix4 worldToCamera{};
    float meanDepth = 0.0f;
    // Temporal state (docs/MODEL.md sections 3 and 7).
    FeatureMap embeddingHistory, radianceHistory, output, lastFeatures;
    // Every map with as many channels as the network's layers comes from the pool and goes back
    // as soon as it is dead; the few-channel maps below are kept from frame to frame.
    FeatureMapPool pool;
    FeatureMap radiance, historyRadiance, temporalBandwidth, lambda, filterA, filterB, warpedOutput, validMap;
    std::vector<FeatureMap> kernelBandwidth, kernelCentre;

    State(Model m, DenoiserOptions o) : model(std::move(m)), options(o) {}
    FeatureMap runUnet(const Network& net, const FeatureMap& embedding, const FeatureMap& historyEmbedding);
    // Applies the convolutions of `block` in turn to `map`, each output replacing its input.
    void runBlock(const std::vector<Conv2d>& block, std::size_t first, FeatureMap& map);
};

Denoiser::Denoiser(Model model, DenoiserOptions options)
    : state_(std::make_unique<State>(std::move(model), options)) {}
Denoiser::~Denoiser() = default;
Denoiser::Denoiser(Denoiser&&) noexcept = default;
Denoiser& Denoiser::operator=(Denoiser&&) noexcept = default;

const Model& Denoiser::model() const { return state_->model; }
const DenoiserOptions& Denoiser::options() const { return state_->options; }

void Denoiser::reset() { state_->hasHistory = false; }

void Denoiser::State::runBlock(const std::vector<Conv2d>& block, std::size_t first, FeatureMap& map) {
    for (std::size_t j = first; j < block.size(); ++j) {
        FeatureMap next = pool.take(map.height(), map.width(), block[j].outChannels());
        block[j].apply(map, Activation::LeakyRelu, next);
        pool.give(map);
        map = std::move(next);
    }
}

// The head's output: U-Net(concat(embedding, historyEmbedding)).
FeatureMap Denoiser::State::runUnet(const Network& net, const FeatureMap& embedding,
                                    const FeatureMap& historyEmbedding) {
    const std::size_t levels = net.encoder.size();
    std::vector<FeatureMap> encoderOut(levels);  // the skip connections
    for (std::size_t level = 0; level < levels; ++level) {
        const std::vector<Conv2d>& block = net.encoder[level];
        FeatureMap& out = encoderOut[level];
        if (level == 0) {
            out = pool.take(embedding.height(), embedding.width(), block[0].outChannels());
            block[0].apply(embedding, historyEmbedding, Activation::LeakyRelu, out);
        } else {
            const FeatureMap& above = encoderOut[level - 1];
            FeatureMap pooled = pool.take((above.height() + 1) / 2, (above.width() + 1) / 2, above.channels());
            maxPool2x2(above, pooled);
            out = pool.take(pooled.height(), pooled.width(), block[0].outChannels());
            block[0].apply(pooled, Activation::LeakyRelu, out);
            pool.give(pooled);
        }
        runBlock(block, 1, out);
    }
    const FeatureMap& deepest = encoderOut[levels - 1];
    FeatureMap low = pool.take((deepest.height() + 1) / 2, (deepest.width() + 1) / 2, deepest.channels());
    maxPool2x2(deepest, low);
    runBlock(net.bottleneck, 0, low);
    for (std::size_t l = levels; l-- > 0;) {
        FeatureMap& skip = encoderOut[l];
        FeatureMap upsampled = pool.take(skip.height(), skip.width(), low.channels());
        upsampleNearest(low, skip.height(), skip.width(), upsampled);
        pool.give(low);
        const std::vector<Conv2d>& block = net.decoder[l];
        low = pool.take(skip.height(), skip.width(), block[0].outChannels());
        block[0].apply(upsampled, skip, Activation::LeakyRelu, low);
        pool.give(upsampled);
        pool.give(skip);
        runBlock(block, 1, low);
    }
    FeatureMap head = pool.take(low.height(), low.width(), net.head->outChannels());
    net.head->apply(low, Activation::None, head);
    pool.give(low);
    return head;
}

std::vector<float> Denoiser::denoise(const SampleFrame& frame, DenoiseReport* report) {
    if (frame.width() < 1 || frame.height() < 1 || frame.spp() < 1) throw Error("denoise: the frame is empty");
    SampleFrameView view;
    try {
        view = frame.view();
    } catch (const Error& e) {
        throw Error(std::string("denoise: ") + e.what());
    }
    return denoise(view, report);
}

std::vector<float> Denoiser::denoise(const SampleFrameView& frame, DenoiseReport* report) {
    State& s = *state_;
    const Network& net = s.model.network();
    DenoiseReport local;
    StageClock clock(local);
    const int width = frame.width, height = frame.height;
    if (width < 1 || height < 1 || frame.spp < 1) throw Error("denoise: the frame is empty");
    if (!frame.samples || !frame.motion || !frame.valid) throw Error("denoise: the frame lacks a buffer");

    // Drop history where it cannot apply.
    const float scale = depthScale(frame);
    const float meanDepth = scale > 0.0f ? 1.0f / scale : 0.0f;
    if (s.hasHistory) {
        double degrees = 0.0, distance = 0.0;
        cameraChange(s.worldToCamera, frame.info.worldToCamera, degrees, distance);
        if (width != s.width || height != s.height)
            local.resetReason = "frame size changed";
        else if (degrees > 45.0)
            local.resetReason = "camera turned by " + std::to_string(int(degrees)) + " degrees";
        else if (meanDepth > 0.0f && distance > 0.5 * std::max(meanDepth, s.meanDepth))
            local.resetReason = "camera moved by more than half the scene depth";
        if (!local.resetReason.empty()) s.hasHistory = false;
    }
    s.width = width;
    s.height = height;
    s.worldToCamera = frame.info.worldToCamera;
    s.meanDepth = meanDepth;
    if (!s.options.useHistory) s.hasHistory = false;
    const bool history = s.hasHistory;
    local.usedHistory = history;

    // 1-2. Per-sample embedding averaged per pixel; noisy radiance.
    const int E = net.embedding->outChannels();
    FeatureMap embedding = s.pool.take(height, width, E);
    local.invalidRadiance = net.embedding->apply(frame.samples, height, width, frame.spp, scale, embedding);
    noisyRadiance(frame, s.radiance);
    clock.mark("embedding");

    // 3. Histories: warped previous state where valid, the current frame elsewhere.
    const float* valid = frame.valid;  // read only when there is history
    FeatureMap historyEmbedding = s.pool.take(height, width, E);
    if (history) {
        warpBilinear(s.embeddingHistory, frame.motion, historyEmbedding);
        keepWhereValid(historyEmbedding, embedding, valid);
        warpBilinear(s.radianceHistory, frame.motion, s.historyRadiance);
        keepWhereValid(s.historyRadiance, s.radiance, valid);
    } else {
        historyEmbedding = embedding;
        s.historyRadiance = s.radiance;
    }
    s.pool.give(s.embeddingHistory);  // read: its memory serves the U-Net
    clock.mark("warp history");

    // 4-5. U-Net and per-pixel parameters.
    FeatureMap head = s.runUnet(net, embedding, historyEmbedding);
    clock.mark("u-net");
    const int K = net.kernels, F = net.affinityFeatures;
    std::vector<FeatureMap> kernelFeatures(static_cast<std::size_t>(K));
    s.kernelBandwidth.resize(std::size_t(K));
    s.kernelCentre.resize(std::size_t(K));
    for (std::size_t k = 0; k < std::size_t(K); ++k) {
        kernelFeatures[k] = s.pool.take(height, width, F);
        s.kernelBandwidth[k].resize(height, width, 1);
        s.kernelCentre[k].resize(height, width, 1);
    }
    s.temporalBandwidth.resize(height, width, 1);
    s.lambda.resize(height, width, 1);
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const float* o = head.pixel(y, x);
            for (std::size_t k = 0; k < std::size_t(K); ++k) {
                const float* base = o + int(k) * (F + 2);
                std::copy(base, base + F, kernelFeatures[k].pixel(y, x));
                s.kernelBandwidth[k].pixel(y, x)[0] = base[F];
                s.kernelCentre[k].pixel(y, x)[0] = sigmoid(base[F + 1]);
            }
            s.temporalBandwidth.pixel(y, x)[0] = o[K * (F + 2)];
            s.lambda.pixel(y, x)[0] = sigmoid(o[K * (F + 2) + 1]);
        }
    s.pool.give(head);

    // 3 (continued). Accumulate with the learned lambda; keep for the next frame.
    blendInto(embedding, s.lambda, historyEmbedding);
    s.embeddingHistory = std::move(historyEmbedding);
    s.pool.give(embedding);
    blend(s.radiance, s.historyRadiance, s.lambda, s.filterA);
    s.radianceHistory = s.filterA;
    clock.mark("kernel parameters and accumulation");

    // 6. Dilated spatial kernels on the accumulated radiance.
    auto params = [&](int k) {
        return KernelParams{&kernelFeatures[std::size_t(k)], &s.kernelBandwidth[std::size_t(k)],
                            &s.kernelCentre[std::size_t(k)]};
    };
    FeatureMap* in = &s.filterA;
    FeatureMap* out = &s.filterB;
    for (int k = s.options.allKernels ? 0 : K - 1; k + 1 < K; ++k) {
        affinityFilter(*in, params(k), net.tapSize, 1 << k, *out);
        std::swap(in, out);
    }
    clock.mark("spatial kernels");
    // 7. The last kernel, with temporal taps on the warped previous output.
    if (history && s.options.temporalKernel) {
        warpBilinear(s.output, frame.motion, s.warpedOutput);
        FeatureMap warpedFeatures = s.pool.take(height, width, F);
        warpBilinear(s.lastFeatures, frame.motion, warpedFeatures);
        s.validMap.resize(height, width, 1);
        std::copy(valid, valid + frame.pixelCount(), s.validMap.data());
        affinityFilterTemporal(*in, params(K - 1), net.tapSize, 1 << (K - 1), s.temporalBandwidth, s.warpedOutput,
                               warpedFeatures, s.validMap, *out);
        s.pool.give(warpedFeatures);
    } else {
        affinityFilter(*in, params(K - 1), net.tapSize, 1 << (K - 1), *out);
    }
    std::swap(s.output, *out);
    s.pool.give(s.lastFeatures);
    s.lastFeatures = std::move(kernelFeatures[std::size_t(K - 1)]);
    for (FeatureMap& map : kernelFeatures) s.pool.give(map);
    s.hasHistory = true;
    clock.mark("temporal kernel");

    if (report) *report = local;
    return std::vector<float>(s.output.data(), s.output.data() + s.output.size());
}

}  // namespace affinity
