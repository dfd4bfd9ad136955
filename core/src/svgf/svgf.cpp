// SVGF (Schied et al. 2017), one method per stage: prepare guides -> reproject and accumulate
// -> spatial variance where history is short -> a-trous passes -> remodulate -> keep history.
// Images are planes of floats (one channel each) padded left and right, so that the a-trous
// taps and the eight-lane vector loads near the borders read zeros instead of running off a
// row; an `inside` plane (1 in the image, 0 in the padding) masks those taps out.
#include "affinity/svgf.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <string>

#include "affinity/error.h"
#include "kernels/fast_exp.h"
#include "kernels/luminance.h"

namespace affinity {
namespace {

constexpr int kLanes = 8;
// Rec. 709 luminance (kernels/luminance.h), as in the paper's implementation.
// Illumination is clamped here so that squared luminances and their sums stay finite.
constexpr float kMaxIllumination = 1e18f;
// Edge-stopping denominators: epsilon of the depth term relative to the pixel's depth (our
// depth is a world-space distance, so a fixed epsilon would depend on the scene's scale), and
// the luminance term's epsilon.
constexpr float kDepthRelativeEpsilon = 1e-3f;
constexpr float kLuminanceEpsilon = 1e-10f;
// Reprojection depth test: the absolute part of the tolerance, relative to the pixel's depth.
constexpr float kReprojectRelativeDepth = 2e-3f;
// Bilinear weight a reprojection must keep after rejecting taps to count as history.
constexpr float kMinReprojectionWeight = 0.01f;
// Edge-stopping weights below this are 0: they change nothing, and their squares (the
// variance filter) would be denormal numbers, which cost some processors a hundred cycles.
constexpr float kMinWeight = 1e-12f;
constexpr float kMaxExponent = 30.0f;
// The 1D B3-spline taps of the a-trous kernel at offsets 0, 1, 2: 3/8, 1/4, 1/16.
constexpr std::array<float, 3> kAtrousKernel{0.375f, 0.25f, 0.0625f};
constexpr int kSpatialVarianceRadius = 3;  // the 7x7 bilateral estimate

// What the reprojection reads of the previous frame, interleaved per pixel (one cache line per
// bilinear tap instead of eleven planes).
namespace previous {
inline constexpr int kColour = 0;   // 3: illumination after the feedback pass
inline constexpr int kMoments = 3;  // 2: integrated luminance moments
inline constexpr int kHistory = 5;  // 1: history length
inline constexpr int kDepth = 6;    // 1
inline constexpr int kNormal = 7;   // 4: normal and miss marker
inline constexpr int kSize = 12;
}  // namespace previous

inline Vec8f load8(const float* p) {
    Vec8f v;
    std::memcpy(&v, p, sizeof v);
    return v;
}
inline void store8(float* p, Vec8f v, int lanes) { std::memcpy(p, &v, sizeof(float) * std::size_t(lanes)); }
inline Vec8f abs8(Vec8f v) { return v < 0.0f ? -v : v; }
inline Vec8f min8(Vec8f a, Vec8f b) { return a < b ? a : b; }
inline Vec8f max8(Vec8f a, Vec8f b) { return a > b ? a : b; }

float luminance(float r, float g, float b) { return kLumaR * r + kLumaG * g + kLumaB * b; }
inline Vec8f luminance8(Vec8f r, Vec8f g, Vec8f b) { return kLumaR * r + kLumaG * g + kLumaB * b; }

// Where planes put pixel (x, y): rows of `stride` floats with `pad` floats of zeros before the
// image and at least pad + kLanes after it.
struct Layout {
    int width = 0, height = 0, pad = 0;
    std::size_t stride = 0;
    std::size_t at(int x, int y) const { return std::size_t(y) * stride + std::size_t(pad + x); }
    std::size_t size() const { return std::size_t(height) * stride; }
    bool operator==(const Layout&) const = default;
};

// Why a frame's buffers cannot be filtered, if they cannot.
void checkFrame(const SampleFrameView& frame) {
    if (frame.width < 1 || frame.height < 1 || frame.spp < 1) throw Error("svgf: the frame is empty");
    if (!frame.samples || !frame.motion || !frame.valid) throw Error("svgf: the frame lacks a buffer");
}

void checkSettings(const SvgfSettings& s) {
    const auto fail = [](const std::string& what) { throw Error("svgf settings: " + what); };
    if (s.atrousIterations < 0 || s.atrousIterations > 10) fail("atrousIterations must be in 0..10");
    if (s.feedbackIteration < 0 || s.feedbackIteration >= std::max(1, s.atrousIterations))
        fail("feedbackIteration must be in 0..atrousIterations - 1");
    if (!(s.sigmaDepth >= 0.0f) || !std::isfinite(s.sigmaDepth)) fail("sigmaDepth must be finite and >= 0");
    if (!(s.sigmaNormal >= 0.0f) || !(s.sigmaNormal <= 1e6f)) fail("sigmaNormal must be in [0, 1e6]");
    if (!(s.sigmaLuminance > 0.0f) || !std::isfinite(s.sigmaLuminance)) fail("sigmaLuminance must be finite and > 0");
    if (!(s.alphaColor > 0.0f && s.alphaColor <= 1.0f)) fail("alphaColor must be in (0, 1]");
    if (!(s.alphaMoments > 0.0f && s.alphaMoments <= 1.0f)) fail("alphaMoments must be in (0, 1]");
    if (s.historyCap < 1) fail("historyCap must be >= 1");
    if (s.spatialVarianceFrames < 0) fail("spatialVarianceFrames must be >= 0");
    if (!(s.reprojectDepthTolerance >= 0.0f)) fail("reprojectDepthTolerance must be >= 0");
    if (!(s.reprojectNormalCosine >= -1.0f && s.reprojectNormalCosine <= 1.0f))
        fail("reprojectNormalCosine must be in [-1, 1]");
    if (!(s.albedoEpsilon > 0.0f && s.albedoEpsilon <= 1.0f)) fail("albedoEpsilon must be in (0, 1]");
}

// max(0, n(p) . n(q))^sigma_n on eight lanes. Cosines whose power would be below 1e-13 are
// cut to 0 first, so that no step of the power is a denormal number.
class NormalWeight {
public:
    explicit NormalWeight(float sigma) : sigma_(sigma), cutoff_(sigma > 0.0f ? std::exp(-kMaxExponent / sigma) : 0.0f) {
        const float rounded = std::round(sigma);
        integral_ = rounded == sigma && sigma <= 65536.0f;
        exponent_ = integral_ ? unsigned(rounded) : 0u;
    }

    Vec8f operator()(Vec8f cosine) const {
        const Vec8f base = cosine < cutoff_ ? Vec8f{} : cosine;
        if (integral_) {
            Vec8f result = broadcast8(1.0f), power = base;
            for (unsigned e = exponent_; e != 0; e >>= 1) {
                if (e & 1u) result *= power;
                if (e > 1) power *= power;
            }
            return result;
        }
        Vec8f result;
        for (int l = 0; l < kLanes; ++l) result[l] = std::pow(base[l], sigma_);
        return result;
    }

private:
    float sigma_, cutoff_;
    bool integral_ = false;
    unsigned exponent_ = 0;
};

// The centre pixels of an eight-lane strip: what the edge-stopping functions compare with.
struct CentreGuides {
    Vec8f depth, depthScale, depthEpsilon, nx, ny, nz, nw;
};

}  // namespace

struct Svgf::State {
    SvgfSettings settings;
    NormalWeight normalWeight;
    Layout layout;
    bool hasHistory = false;

    // This frame's guides, padded: mean depth, sigma_z |grad z|, max(|dz/dx|, |dz/dy|), the unit
    // mean normal plus a fourth component that is 1 on misses (so misses match each other and
    // nothing else), and the inside mask.
    std::vector<float> depth, depthScale, depthWidth, inside;
    std::array<std::vector<float>, 4> normal;
    // Demodulation factors max(albedo, eps) per channel, and the emitted radiance, which is
    // added back after filtering.
    std::array<std::vector<float>, 3> albedo, emitted;
    // Filter state: illumination and its variance, ping-ponged between a-trous passes; the
    // integrated luminance moments and history length; 1 / (sigma_l sqrt(g3x3(variance)) + eps).
    std::array<std::array<std::vector<float>, 3>, 2> colour;
    std::array<std::vector<float>, 2> variance, moments;
    std::vector<float> history, luminanceScale;
    // The previous frame, read by the reprojection: previous::kSize floats per pixel, unpadded.
    std::vector<float> previousFrame;

    explicit State(const SvgfSettings& s) : settings(s), normalWeight(s.sigmaNormal) {}

    void allocate(int width, int height);
    void prepareGuides(const SampleFrameView& frame);
    void computeDepthGradients();
    void reprojectAndAccumulate(const SampleFrameView& frame, bool useHistory);
    void estimateSpatialVariance();
    void prefilterVariance(const std::vector<float>& varianceIn);
    void atrousPass(int step, int from, int to);
    std::vector<float> remodulate(int from) const;
    void keepColour(int from);
    void keepHistory();

    CentreGuides centreGuides(std::size_t i) const {
        CentreGuides c;
        c.depth = load8(depth.data() + i);
        c.depthScale = load8(depthScale.data() + i);
        c.depthEpsilon = kDepthRelativeEpsilon * c.depth + 1e-20f;
        c.nx = load8(normal[0].data() + i);
        c.ny = load8(normal[1].data() + i);
        c.nz = load8(normal[2].data() + i);
        c.nw = load8(normal[3].data() + i);
        return c;
    }
    // Depth exponent |z(p) - z(q)| / (sigma_z |grad z(p)| |p - q| + eps) and normal weight of the
    // strip's taps at plane index j, |p - q| = distance pixels away. The paper projects the
    // gradient on p - q; our depth is the mean of jittered samples, noisy along the isophotes
    // where that projection is 0, so we use its bound |grad z| |p - q| (as the paper's
    // implementation does with fwidth).
    void guideTerms(const CentreGuides& c, std::size_t j, float distance, Vec8f& depthExponent,
                    Vec8f& normalTerm) const {
        depthExponent = abs8(c.depth - load8(depth.data() + j)) / (c.depthScale * distance + c.depthEpsilon);
        const Vec8f cosine = c.nx * load8(normal[0].data() + j) + c.ny * load8(normal[1].data() + j) +
                             c.nz * load8(normal[2].data() + j) + c.nw * load8(normal[3].data() + j);
        normalTerm = normalWeight(cosine) * load8(inside.data() + j);
    }
};

namespace {

// weight = spatial * normalTerm * exp(-exponent), with tiny weights cut to 0 (see kMinWeight).
inline Vec8f edgeWeight(float spatial, Vec8f normalTerm, Vec8f exponent) {
    const Vec8f w = (spatial * normalTerm) * fastExpNonPositive(-min8(exponent, broadcast8(kMaxExponent)));
    return w < kMinWeight ? Vec8f{} : w;
}

}  // namespace

void Svgf::State::allocate(int width, int height) {
    Layout next;
    next.width = width;
    next.height = height;
    // The widest a-trous tap is 2 * 2^(iterations - 1) pixels away, the spatial variance 3;
    // taps at least a row's width away are skipped, never read.
    const int reach =
        std::max(kSpatialVarianceRadius, settings.atrousIterations > 0 ? 1 << settings.atrousIterations : 0);
    next.pad = std::max(1, std::min(reach, width - 1));
    next.stride = std::size_t(2 * next.pad + width + kLanes);
    if (next == layout) return;
    layout = next;
    const std::size_t n = layout.size();
    // Zero everywhere: the padding is never written afterwards and must stay 0.
    for (std::vector<float>* plane : {&depth, &depthScale, &depthWidth, &inside, &history, &luminanceScale})
        plane->assign(n, 0.0f);
    for (int c = 0; c < 4; ++c) normal[c].assign(n, 0.0f);
    for (int c = 0; c < 3; ++c) {
        albedo[c].assign(n, 0.0f);
        emitted[c].assign(n, 0.0f);
        colour[0][c].assign(n, 0.0f);
        colour[1][c].assign(n, 0.0f);
    }
    for (int k = 0; k < 2; ++k) {
        variance[k].assign(n, 0.0f);
        moments[k].assign(n, 0.0f);
    }
    previousFrame.assign(std::size_t(width) * std::size_t(height) * previous::kSize, 0.0f);
    for (int y = 0; y < height; ++y) std::fill_n(inside.begin() + std::ptrdiff_t(layout.at(0, y)), width, 1.0f);
}

Svgf::Svgf(SvgfSettings settings) {
    checkSettings(settings);
    state_ = std::make_unique<State>(settings);
}
Svgf::~Svgf() = default;
Svgf::Svgf(Svgf&&) noexcept = default;
Svgf& Svgf::operator=(Svgf&&) noexcept = default;

const SvgfSettings& Svgf::settings() const { return state_->settings; }

void Svgf::reset() { state_->hasHistory = false; }

std::vector<float> Svgf::historyLength() const {
    const State& s = *state_;
    std::vector<float> lengths;
    if (!s.hasHistory) return lengths;
    lengths.reserve(std::size_t(s.layout.width) * std::size_t(s.layout.height));
    for (int y = 0; y < s.layout.height; ++y) {
        const float* row = s.history.data() + s.layout.at(0, y);
        lengths.insert(lengths.end(), row, row + s.layout.width);
    }
    return lengths;
}

// Per pixel from the samples (non-finite and negative radiance read as 0): the radiance of
// samples whose first non-specular vertex emits or that escaped to the sky (the emissive flag)
// into `emitted`, left unfiltered as the paper's implementation adds emission after
// remodulating; the rest demodulated, illumination = radiance / max(albedo, eps), into
// colour[0] with albedo the mean over the samples (emissive ones counting 0, so that partial
// coverage is demodulated too); over the other samples, the mean of the finite positive
// depths and the normalised mean normal, or the miss marker where there are none (the sky,
// lamps: nothing to filter there).
void Svgf::State::prepareGuides(const SampleFrameView& frame) {
    const int width = frame.width, height = frame.height, spp = frame.spp;
    const float inverseSpp = 1.0f / float(spp);
    const float epsilon = settings.albedoEpsilon;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            float radiance[3] = {0, 0, 0}, emission[3] = {0, 0, 0}, reflectance[3] = {0, 0, 0}, n[3] = {0, 0, 0};
            float depthSum = 0.0f;
            int hits = 0;
            for (int s = 0; s < spp; ++s) {
                const float* f = frame.sample(x, y, s);
                const bool emissive = f[channel::kEmissive] > 0.5f;
                for (int c = 0; c < 3; ++c) {
                    const float d = f[channel::kDiffuse + c], sp = f[channel::kSpecular + c];
                    const float value =
                        (std::isfinite(d) && d > 0.0f ? d : 0.0f) + (std::isfinite(sp) && sp > 0.0f ? sp : 0.0f);
                    const float a = f[channel::kAlbedo + c];
                    if (emissive) {
                        emission[c] += value;
                    } else {
                        radiance[c] += value;
                        reflectance[c] += std::isfinite(a) && a > 0.0f ? a : 0.0f;
                    }
                }
                const float z = f[channel::kDepth];
                if (!emissive && std::isfinite(z) && z > 0.0f) {
                    depthSum += z;
                    ++hits;
                    for (int c = 0; c < 3; ++c)
                        if (std::isfinite(f[channel::kNormal + c])) n[c] += f[channel::kNormal + c];
                }
            }
            const std::size_t i = layout.at(x, y);
            for (int c = 0; c < 3; ++c) {
                const float factor = std::max(reflectance[c] * inverseSpp, epsilon);
                albedo[c][i] = factor;
                emitted[c][i] = std::min(emission[c] * inverseSpp, kMaxIllumination);
                colour[0][c][i] = std::min(radiance[c] * inverseSpp / factor, kMaxIllumination);
            }
            const float length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            const float scale = length > 0.0f ? 1.0f / length : 0.0f;
            for (int c = 0; c < 3; ++c) normal[c][i] = n[c] * scale;
            normal[3][i] = hits == 0 ? 1.0f : 0.0f;
            depth[i] = hits > 0 ? depthSum / float(hits) : 0.0f;
        }
}

// Screen-space depth derivatives: along each axis the one-sided difference of smaller magnitude
// towards a neighbour that hit something, so that a pixel beside a depth edge takes the slope
// of its own surface. Writes depthScale = sigma_z |grad z| and depthWidth = max(|dz/dx|, |dz/dy|).
void Svgf::State::computeDepthGradients() {
    const int width = layout.width, height = layout.height;
    // |z(j) - z(i)| for the neighbour j (of `count`) closest in depth that hit something; 0 if none.
    const auto derivative = [&](std::size_t i, const std::size_t* neighbours, int count) {
        float best = -1.0f;
        for (int k = 0; k < count; ++k) {
            const std::size_t j = neighbours[k];
            if (normal[3][j] != 0.0f) continue;
            const float d = std::abs(depth[j] - depth[i]);
            if (best < 0.0f || d < best) best = d;
        }
        return std::max(best, 0.0f);
    };
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const std::size_t i = layout.at(x, y);
            float gx = 0.0f, gy = 0.0f;
            if (normal[3][i] == 0.0f) {
                std::size_t horizontal[2] = {0, 0}, vertical[2] = {0, 0};
                int h = 0, v = 0;
                if (x > 0) horizontal[h++] = i - 1;
                if (x + 1 < width) horizontal[h++] = i + 1;
                if (y > 0) vertical[v++] = i - layout.stride;
                if (y + 1 < height) vertical[v++] = i + layout.stride;
                gx = derivative(i, horizontal, h);
                gy = derivative(i, vertical, v);
            }
            depthScale[i] = settings.sigmaDepth * std::sqrt(gx * gx + gy * gy);
            depthWidth[i] = std::max(gx, gy);
        }
}

// Reads colour[0] (this frame's illumination), the guides and the previous frame's buffers;
// writes colour[0] (integrated illumination), moments[0..1] (integrated luminance moments),
// history (frames accumulated) and variance[0] (temporal luminance variance).
void Svgf::State::reprojectAndAccumulate(const SampleFrameView& frame, bool useHistory) {
    const int width = layout.width, height = layout.height;
    const float cap = float(settings.historyCap);
    const float* past = previousFrame.data();
    float* const out[3] = {colour[0][0].data(), colour[0][1].data(), colour[0][2].data()};
    float *moment1 = moments[0].data(), *moment2 = moments[1].data(), *lengths = history.data();
    float* varianceOut = variance[0].data();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const std::size_t i = layout.at(x, y);
            float c[3] = {out[0][i], out[1][i], out[2][i]};
            const float l = luminance(c[0], c[1], c[2]);
            float m[2] = {l, l * l};

            float sumWeight = 0.0f, sumHistory = 0.0f, sumColour[3] = {0, 0, 0}, sumMoments[2] = {0, 0};
            const std::size_t pixel = std::size_t(y) * std::size_t(width) + std::size_t(x);
            const float* motion = frame.motion + 2 * pixel;
            // The previous frame's pixel centres are at integer + 0.5, as ours.
            const float px = float(x) + motion[0], py = float(y) + motion[1];
            if (useHistory && frame.valid[pixel] >= 0.5f && px > -1.0f && px < float(width) && py > -1.0f &&
                py < float(height)) {
                const int x0 = int(std::floor(px)), y0 = int(std::floor(py));
                const float fx = px - float(x0), fy = py - float(y0);
                const float z = depth[i];
                const float tolerance =
                    settings.reprojectDepthTolerance * (depthWidth[i] + kReprojectRelativeDepth * z);
                const float n[4] = {normal[0][i], normal[1][i], normal[2][i], normal[3][i]};
                for (int tap = 0; tap < 4; ++tap) {
                    const int tx = x0 + (tap & 1), ty = y0 + (tap >> 1);
                    const float w = ((tap & 1) ? fx : 1.0f - fx) * ((tap >> 1) ? fy : 1.0f - fy);
                    if (tx < 0 || tx >= width || ty < 0 || ty >= height || w <= 0.0f) continue;
                    const float* p = past + (std::size_t(ty) * std::size_t(width) + std::size_t(tx)) * previous::kSize;
                    if (std::abs(p[previous::kDepth] - z) > tolerance) continue;
                    float cosine = 0.0f;
                    for (int k = 0; k < 4; ++k) cosine += n[k] * p[previous::kNormal + k];
                    if (cosine < settings.reprojectNormalCosine) continue;
                    sumWeight += w;
                    for (int k = 0; k < 3; ++k) sumColour[k] += w * p[previous::kColour + k];
                    for (int k = 0; k < 2; ++k) sumMoments[k] += w * p[previous::kMoments + k];
                    sumHistory += w * p[previous::kHistory];
                }
            }
            float length = 1.0f;
            if (sumWeight >= kMinReprojectionWeight) {
                const float inverse = 1.0f / sumWeight;
                length = std::min(cap, sumHistory * inverse + 1.0f);
                // 1 / length: a plain average until the moving average's weight is reached.
                const float alpha = std::max(settings.alphaColor, 1.0f / length);
                const float alphaMoments = std::max(settings.alphaMoments, 1.0f / length);
                for (int k = 0; k < 3; ++k) c[k] = alpha * c[k] + (1.0f - alpha) * sumColour[k] * inverse;
                for (int k = 0; k < 2; ++k)
                    m[k] = alphaMoments * m[k] + (1.0f - alphaMoments) * sumMoments[k] * inverse;
            }
            for (int k = 0; k < 3; ++k) out[k][i] = c[k];
            moment1[i] = m[0];
            moment2[i] = m[1];
            lengths[i] = length;
            varianceOut[i] = std::max(0.0f, m[1] - m[0] * m[0]);
        }
}

// Where history is shorter than spatialVarianceFrames, replaces variance[0] by the variance of
// the integrated moments over a 7x7 window, weighted by the depth and normal edge-stopping
// functions (paper section 4.2).
void Svgf::State::estimateSpatialVariance() {
    const int width = layout.width, height = layout.height;
    const float threshold = float(settings.spatialVarianceFrames);
    const int r = kSpatialVarianceRadius;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; x += kLanes) {
            const int lanes = std::min(kLanes, width - x);
            const std::size_t i = layout.at(x, y);
            bool needed = false;
            for (int l = 0; l < lanes; ++l) needed = needed || history[i + std::size_t(l)] < threshold;
            if (!needed) continue;
            const CentreGuides centre = centreGuides(i);
            Vec8f sumWeight = broadcast8(1.0f), sum1 = load8(moments[0].data() + i),
                  sum2 = load8(moments[1].data() + i);
            for (int dy = -r; dy <= r; ++dy) {
                if (y + dy < 0 || y + dy >= height) continue;
                for (int dx = -r; dx <= r; ++dx) {
                    if ((dx == 0 && dy == 0) || std::abs(dx) >= width) continue;
                    const std::size_t j = layout.at(x + dx, y + dy);
                    Vec8f depthExponent, normalTerm;
                    guideTerms(centre, j, std::sqrt(float(dx * dx + dy * dy)), depthExponent, normalTerm);
                    const Vec8f w = edgeWeight(1.0f, normalTerm, depthExponent);
                    sumWeight += w;
                    sum1 += w * load8(moments[0].data() + j);
                    sum2 += w * load8(moments[1].data() + j);
                }
            }
            const Vec8f mean = sum1 / sumWeight;
            const Vec8f spatial = max8(Vec8f{}, sum2 / sumWeight - mean * mean);
            for (int l = 0; l < lanes; ++l)
                if (history[i + std::size_t(l)] < threshold) variance[0][i + std::size_t(l)] = spatial[l];
        }
}

// luminanceScale = 1 / (sigma_l sqrt(g3x3 * variance) + eps), the 3x3 Gaussian renormalised
// over the pixels inside the image.
void Svgf::State::prefilterVariance(const std::vector<float>& varianceIn) {
    const int width = layout.width, height = layout.height;
    constexpr float kGaussian[2] = {0.5f, 0.25f};
    const float *values = varianceIn.data(), *mask = inside.data();
    float* scale = luminanceScale.data();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            float sum = 0.0f, sumWeight = 0.0f;
            for (int dy = -1; dy <= 1; ++dy) {
                if (y + dy < 0 || y + dy >= height) continue;
                for (int dx = -1; dx <= 1; ++dx) {
                    const std::size_t j = layout.at(x + dx, y + dy);
                    const float w = kGaussian[std::abs(dx)] * kGaussian[std::abs(dy)] * mask[j];
                    sum += w * values[j];
                    sumWeight += w;
                }
            }
            scale[layout.at(x, y)] = 1.0f / (settings.sigmaLuminance * std::sqrt(sum / sumWeight) + kLuminanceEpsilon);
        }
}

// One a-trous pass with taps `step` pixels apart: reads colour[from], variance[from] and the
// guides, writes colour[to] and variance[to] (variance filtered with the squared weights).
void Svgf::State::atrousPass(int step, int from, int to) {
    prefilterVariance(variance[from]);
    const int width = layout.width, height = layout.height;
    const std::array<std::vector<float>, 3>& in = colour[from];
    const std::vector<float>& varianceIn = variance[from];
    const float centreKernel = kAtrousKernel[0] * kAtrousKernel[0];
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; x += kLanes) {
            const std::size_t i = layout.at(x, y);
            const CentreGuides centre = centreGuides(i);
            const Vec8f r0 = load8(in[0].data() + i), g0 = load8(in[1].data() + i), b0 = load8(in[2].data() + i);
            const Vec8f centreLuminance = luminance8(r0, g0, b0);
            const Vec8f scale = load8(luminanceScale.data() + i);
            Vec8f sumWeight = broadcast8(centreKernel);
            Vec8f sumR = centreKernel * r0, sumG = centreKernel * g0, sumB = centreKernel * b0;
            Vec8f sumVariance = (centreKernel * centreKernel) * load8(varianceIn.data() + i);
            for (int dy = -2; dy <= 2; ++dy) {
                const int ty = y + dy * step;
                if (ty < 0 || ty >= height) continue;
                for (int dx = -2; dx <= 2; ++dx) {
                    if ((dx == 0 && dy == 0) || std::abs(dx * step) >= width) continue;
                    const std::size_t j = layout.at(x + dx * step, ty);
                    Vec8f depthExponent, normalTerm;
                    guideTerms(centre, j, float(step) * std::sqrt(float(dx * dx + dy * dy)), depthExponent, normalTerm);
                    const Vec8f r = load8(in[0].data() + j), g = load8(in[1].data() + j), b = load8(in[2].data() + j);
                    const Vec8f luminanceExponent = abs8(centreLuminance - luminance8(r, g, b)) * scale;
                    const Vec8f w = edgeWeight(kAtrousKernel[std::abs(dx)] * kAtrousKernel[std::abs(dy)], normalTerm,
                                               depthExponent + luminanceExponent);
                    sumWeight += w;
                    sumR += w * r;
                    sumG += w * g;
                    sumB += w * b;
                    sumVariance += (w * w) * load8(varianceIn.data() + j);
                }
            }
            const int lanes = std::min(kLanes, width - x);
            const Vec8f inverse = 1.0f / sumWeight;
            store8(colour[to][0].data() + i, sumR * inverse, lanes);
            store8(colour[to][1].data() + i, sumG * inverse, lanes);
            store8(colour[to][2].data() + i, sumB * inverse, lanes);
            store8(variance[to].data() + i, sumVariance * (inverse * inverse), lanes);
        }
}

// Radiance = illumination (colour[from]) * demodulation factors + emitted, height x width x 3.
std::vector<float> Svgf::State::remodulate(int from) const {
    const int width = layout.width, height = layout.height;
    std::vector<float> out(std::size_t(width) * std::size_t(height) * 3);
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const std::size_t i = layout.at(x, y);
            float* o = out.data() + (std::size_t(y) * std::size_t(width) + std::size_t(x)) * 3;
            for (int c = 0; c < 3; ++c) o[c] = colour[from][c][i] * albedo[c][i] + emitted[c][i];
        }
    return out;
}

// The next frame's colour history: colour[from] into previousFrame.
void Svgf::State::keepColour(int from) {
    const int width = layout.width, height = layout.height;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const std::size_t i = layout.at(x, y);
            float* p = previousFrame.data() + (std::size_t(y) * std::size_t(width) + std::size_t(x)) * previous::kSize;
            for (int c = 0; c < 3; ++c) p[previous::kColour + c] = colour[from][c][i];
        }
}

// The rest of the next frame's history: integrated moments, history lengths, depth, normals.
void Svgf::State::keepHistory() {
    const int width = layout.width, height = layout.height;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const std::size_t i = layout.at(x, y);
            float* p = previousFrame.data() + (std::size_t(y) * std::size_t(width) + std::size_t(x)) * previous::kSize;
            p[previous::kMoments] = moments[0][i];
            p[previous::kMoments + 1] = moments[1][i];
            p[previous::kHistory] = history[i];
            p[previous::kDepth] = depth[i];
            for (int k = 0; k < 4; ++k) p[previous::kNormal + k] = normal[k][i];
        }
    hasHistory = true;
}

std::vector<float> Svgf::denoise(const SampleFrame& frame) { return denoise(frame.view("svgf")); }

std::vector<float> Svgf::denoise(const SampleFrameView& frame) {
    checkFrame(frame);
    State& s = *state_;
    if (s.layout.width != frame.width || s.layout.height != frame.height) s.hasHistory = false;
    s.allocate(frame.width, frame.height);

    // Samples -> illumination in colour[0], demodulation factors, depth, normals.
    s.prepareGuides(frame);
    // depth, normals -> depthScale, depthWidth.
    s.computeDepthGradients();
    // colour[0] + previous frame -> integrated colour[0], moments, history, variance[0].
    s.reprojectAndAccumulate(frame, s.hasHistory);
    // moments, guides -> variance[0] where history is short.
    s.estimateSpatialVariance();
    // colour/variance ping-pong; the feedback pass's output (without passes, the integrated
    // colour) becomes the next frame's colour history.
    int current = 0;
    if (s.settings.atrousIterations == 0) s.keepColour(0);
    for (int pass = 0; pass < s.settings.atrousIterations; ++pass) {
        s.atrousPass(1 << pass, current, 1 - current);
        current = 1 - current;
        if (pass == s.settings.feedbackIteration) s.keepColour(current);
    }
    // colour[current] * albedo + emitted -> radiance; moments, history, depth, normals -> previousFrame.
    std::vector<float> out = s.remodulate(current);
    s.keepHistory();
    return out;
}

}  // namespace affinity
