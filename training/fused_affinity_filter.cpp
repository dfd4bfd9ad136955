#include "fused_affinity_filter.h"

#include <ATen/ATen.h>
#include <ATen/Dispatch.h>
#include <ATen/Parallel.h>
#include <torch/autograd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "affinity/error.h"
#include "kernels/fast_exp.h"

namespace affinity::train {
namespace {

using torch::autograd::AutogradContext;
using torch::autograd::tensor_list;

// exp(x) for x <= 0, in place: the core's polynomial in float (vectorised, relative error about
// 2e-7, the inference filter's own), std::exp in double (the gradient checks' precision).
void expNonPositive(float* x, int n) {
    for (int i = 0; i < n; i += 8) {
        const std::size_t bytes = sizeof(float) * std::size_t(std::min(8, n - i));
        Vec8f v{};
        std::memcpy(&v, x + i, bytes);
        v = fastExpNonPositive(v);
        std::memcpy(x + i, &v, bytes);
    }
}
void expNonPositive(double* x, int n) {
    for (int i = 0; i < n; ++i) x[i] = std::exp(x[i]);
}

// Over n pixels in a row: d2 = |fa - fb|^2 across F channels `plane` apart, and the affinity
// e = exp(-band^2 d2).
template <typename T>
void affinities(const T* fa, const T* fb, std::int64_t plane, int F, const T* band, int n, T* d2, T* e) {
    std::fill(d2, d2 + n, T(0));
    for (int ch = 0; ch < F; ++ch) {
        const T* a = fa + ch * plane;
        const T* b = fb + ch * plane;
        for (int k = 0; k < n; ++k) {
            const T d = a[k] - b[k];
            d2[k] += d * d;
        }
    }
    for (int k = 0; k < n; ++k) e[k] = -band[k] * band[k] * d2[k];
    expNonPositive(e, n);
}

struct Tap {
    int dy, dx;
};

// Where a tap at offset (dy, dx) from the pixels of row y lands: its row, and the columns
// [x0, x1) of row y whose tap is inside the image.
struct TapSpan {
    bool inside;
    int row, x0, x1;
};
TapSpan span(const Tap& tap, int y, int height, int width) {
    const int row = y + tap.dy;
    const int x0 = std::max(0, -tap.dx), x1 = std::min(width, width - tap.dx);
    return {row >= 0 && row < height && x0 < x1, row, x0, x1};
}

// One batch element's tensors as planes of height x width values (null where absent).
template <typename T>
struct Element {
    const T* radiance;        // C planes
    const T* features;        // F planes
    const T* bandwidth;       // 1 plane
    const T* centre;          // 1 plane
    const T* tBandwidth;      // 1 plane or null (no temporal taps)
    const T* warpedOutput;    // C planes
    const T* warpedFeatures;  // F planes
    const T* warpedValid;     // 1 plane
};

struct Shape {
    int batch, channels, features, height, width;
    std::int64_t plane() const { return std::int64_t(height) * width; }
};

// Autograd functions take no undefined tensors: an absent input travels as an empty one.
at::Tensor absentAsEmpty(const at::Tensor& tensor, const at::Tensor& like) {
    return tensor.defined() ? tensor : at::empty({0}, like.options());
}
bool present(const at::Tensor& tensor) { return tensor.defined() && tensor.dim() == 4; }

template <typename T>
const T* elementOf(const at::Tensor& tensor, int b) {
    if (!present(tensor)) return nullptr;
    return tensor.data_ptr<T>() + std::int64_t(b) * tensor.size(1) * tensor.size(2) * tensor.size(3);
}
template <typename T>
T* mutableElementOf(at::Tensor& tensor, int b) {
    if (!present(tensor)) return nullptr;
    return tensor.data_ptr<T>() + std::int64_t(b) * tensor.size(1) * tensor.size(2) * tensor.size(3);
}

// Per-thread row buffers.
template <typename T>
struct RowScratch {
    explicit RowScratch(int width) : d2(std::size_t(width)), e(std::size_t(width)), g(std::size_t(width)) {}
    std::vector<T> d2, e, g;
};

std::vector<Tap> spatialTaps(int tapSize, int dilation) {
    std::vector<Tap> taps;
    const int radius = tapSize / 2;
    for (int i = -radius; i <= radius; ++i)
        for (int j = -radius; j <= radius; ++j)
            if (i != 0 || j != 0) taps.push_back({i * dilation, j * dilation});
    return taps;
}

std::vector<Tap> temporalTaps() {
    std::vector<Tap> taps;
    for (int i = -1; i <= 1; ++i)
        for (int j = -1; j <= 1; ++j) taps.push_back({i, j});
    return taps;
}

// Forward of row y: numerator and denominator over the centre, the spatial and the temporal
// taps; out = numerator / (denominator + eps), and that denominator is kept for the backward.
template <typename T>
void forwardRow(const Element<T>& in, const Shape& s, const std::vector<Tap>& spatial, int y, T* out, T* denominator,
                RowScratch<T>& scratch) {
    const std::int64_t plane = s.plane(), row = std::int64_t(y) * s.width;
    T* D = denominator + row;
    for (int x = 0; x < s.width; ++x) D[x] = in.centre[row + x];
    for (int c = 0; c < s.channels; ++c)
        for (int x = 0; x < s.width; ++x)
            out[c * plane + row + x] = in.centre[row + x] * in.radiance[c * plane + row + x];
    // Adds the taps of (values, their features, their validity: null for the spatial taps) at one
    // offset.
    auto addTap = [&](const Tap& tap, const T* values, const T* tapFeatures, const T* tapWeight, const T* bandwidth) {
        const TapSpan sp = span(tap, y, s.height, s.width);
        if (!sp.inside) return;
        const int n = sp.x1 - sp.x0;
        const std::int64_t q = std::int64_t(sp.row) * s.width + sp.x0 + tap.dx, p = row + sp.x0;
        T* e = scratch.e.data();
        affinities(in.features + p, tapFeatures + q, plane, s.features, bandwidth + p, n, scratch.d2.data(), e);
        if (tapWeight)
            for (int k = 0; k < n; ++k) e[k] *= tapWeight[q + k];
        for (int k = 0; k < n; ++k) D[sp.x0 + k] += e[k];
        for (int c = 0; c < s.channels; ++c) {
            T* o = out + c * plane + p;
            const T* v = values + c * plane + q;
            for (int k = 0; k < n; ++k) o[k] += e[k] * v[k];
        }
    };
    for (const Tap& tap : spatial) addTap(tap, in.radiance, in.features, nullptr, in.bandwidth);
    if (in.tBandwidth)
        for (const Tap& tap : temporalTaps())
            addTap(tap, in.warpedOutput, in.warpedFeatures, in.warpedValid, in.tBandwidth);
    for (int x = 0; x < s.width; ++x) D[x] += T(kAffinityEpsilon);
    for (int c = 0; c < s.channels; ++c)
        for (int x = 0; x < s.width; ++x) out[c * plane + row + x] /= D[x];
}

// The gradients of one element's outputs, planes like its inputs (null where not wanted).
template <typename T>
struct Gradients {
    T* radiance;
    T* features;
    T* bandwidth;
    T* centre;
    T* tBandwidth;
    T* warpedOutput;
    T* warpedFeatures;
};

// Backward of row y, every gradient written at this row's own pixels only, so rows run in
// parallel: a pixel's gradients as the filtered pixel p (its centre weight, bandwidths, own
// features), and as a tap q of the pixels p' = q - offset (its radiance or warped output and
// features), the affinity recomputed for each pair. With gN = dL/dout / Z and
// gD = -sum_c gN_c out_c (Z the denominator), a tap's weight W gets G = gD + sum_c gN_c v_c(q).
template <typename T>
void backwardRow(const Element<T>& in, const Shape& s, const std::vector<Tap>& spatial, const T* gN, const T* gD, int y,
                 const Gradients<T>& grad, RowScratch<T>& scratch) {
    const std::int64_t plane = s.plane(), row = std::int64_t(y) * s.width;
    const int C = s.channels, F = s.features;
    for (int x = 0; x < s.width; ++x) {
        T sum = gD[row + x];
        for (int c = 0; c < C; ++c) sum += gN[c * plane + row + x] * in.radiance[c * plane + row + x];
        grad.centre[row + x] = sum;
        for (int c = 0; c < C; ++c) grad.radiance[c * plane + row + x] = in.centre[row + x] * gN[c * plane + row + x];
    }
    T* d2 = scratch.d2.data();
    T* e = scratch.e.data();
    T* g = scratch.g.data();
    // G over n pixels: the filtered pixels at p, the taps' values at q.
    auto tapGradient = [&](std::int64_t p, const T* values, std::int64_t q, int n) {
        for (int k = 0; k < n; ++k) g[k] = gD[p + k];
        for (int c = 0; c < C; ++c)
            for (int k = 0; k < n; ++k) g[k] += gN[c * plane + p + k] * values[c * plane + q + k];
    };
    // This row as the filtered pixels p of the taps q = p + offset.
    auto asFiltered = [&](const Tap& tap, const T* values, const T* tapFeatures, const T* tapWeight, const T* bandwidth,
                          T* bandwidthGradient) {
        const TapSpan sp = span(tap, y, s.height, s.width);
        if (!sp.inside) return;
        const int n = sp.x1 - sp.x0;
        const std::int64_t p = row + sp.x0, q = std::int64_t(sp.row) * s.width + sp.x0 + tap.dx;
        affinities(in.features + p, tapFeatures + q, plane, F, bandwidth + p, n, d2, e);
        tapGradient(p, values, q, n);
        for (int k = 0; k < n; ++k) {
            const T t = g[k] * e[k] * (tapWeight ? tapWeight[q + k] : T(1));  // dL/d(exponent)
            const T a = bandwidth[p + k];
            bandwidthGradient[p + k] += t * T(-2) * a * d2[k];
            g[k] = t * T(-2) * a * a;  // times (f(p) - f(q)) gives dL/df(p)
        }
        for (int ch = 0; ch < F; ++ch)
            for (int k = 0; k < n; ++k)
                grad.features[ch * plane + p + k] +=
                    g[k] * (in.features[ch * plane + p + k] - tapFeatures[ch * plane + q + k]);
    };
    // This row as the taps q of the filtered pixels p = q - offset.
    auto asTap = [&](const Tap& tap, const T* values, const T* tapFeatures, const T* tapWeight, const T* bandwidth,
                     T* valueGradient, T* featureGradient) {
        const TapSpan sp = span({-tap.dy, -tap.dx}, y, s.height, s.width);
        if (!sp.inside) return;
        const int n = sp.x1 - sp.x0;
        const std::int64_t q = row + sp.x0, p = std::int64_t(sp.row) * s.width + sp.x0 - tap.dx;
        affinities(in.features + p, tapFeatures + q, plane, F, bandwidth + p, n, d2, e);
        tapGradient(p, values, q, n);
        for (int c = 0; c < C; ++c)
            for (int k = 0; k < n; ++k)
                valueGradient[c * plane + q + k] +=
                    e[k] * (tapWeight ? tapWeight[q + k] : T(1)) * gN[c * plane + p + k];
        for (int k = 0; k < n; ++k) {
            const T a = bandwidth[p + k];
            g[k] *= e[k] * (tapWeight ? tapWeight[q + k] : T(1)) * T(-2) * a * a;  // times (f(q) - f(p))
        }
        for (int ch = 0; ch < F; ++ch)
            for (int k = 0; k < n; ++k)
                featureGradient[ch * plane + q + k] +=
                    g[k] * (tapFeatures[ch * plane + q + k] - in.features[ch * plane + p + k]);
    };
    for (const Tap& tap : spatial) {
        asFiltered(tap, in.radiance, in.features, nullptr, in.bandwidth, grad.bandwidth);
        asTap(tap, in.radiance, in.features, nullptr, in.bandwidth, grad.radiance, grad.features);
    }
    if (in.tBandwidth) {
        for (const Tap& tap : temporalTaps()) {
            asFiltered(tap, in.warpedOutput, in.warpedFeatures, in.warpedValid, in.tBandwidth, grad.tBandwidth);
            asTap(tap, in.warpedOutput, in.warpedFeatures, in.warpedValid, in.tBandwidth, grad.warpedOutput,
                  grad.warpedFeatures);
        }
    }
}

Shape shapeOf(const at::Tensor& radiance, const at::Tensor& features) {
    return {int(radiance.size(0)), int(radiance.size(1)), int(features.size(1)), int(radiance.size(2)),
            int(radiance.size(3))};
}

template <typename T>
Element<T> elementAt(const tensor_list& t, int b) {
    return {elementOf<T>(t[0], b), elementOf<T>(t[1], b), elementOf<T>(t[2], b), elementOf<T>(t[3], b),
            elementOf<T>(t[4], b), elementOf<T>(t[5], b), elementOf<T>(t[6], b), elementOf<T>(t[7], b)};
}

// Rows of all batch elements in parallel, each thread with its own scratch.
template <typename T, typename RowFunction>
void forEachRow(const Shape& s, RowFunction&& rowFunction) {
    at::parallel_for(0, std::int64_t(s.batch) * s.height, 4, [&](std::int64_t begin, std::int64_t end) {
        RowScratch<T> scratch(s.width);
        for (std::int64_t i = begin; i < end; ++i) rowFunction(int(i / s.height), int(i % s.height), scratch);
    });
}

struct FusedAffinityFilter : public torch::autograd::Function<FusedAffinityFilter> {
    // inputs: radiance, features, bandwidth, centre, temporal bandwidth, warped output, warped
    // features, warped validity (the last four empty without temporal taps).
    static at::Tensor forward(AutogradContext* ctx, const at::Tensor& radiance, const at::Tensor& features,
                              const at::Tensor& bandwidth, const at::Tensor& centre, const at::Tensor& tBandwidth,
                              const at::Tensor& warpedOutput, const at::Tensor& warpedFeatures,
                              const at::Tensor& warpedValid, std::int64_t tapSize, std::int64_t dilation) {
        auto contiguous = [](const at::Tensor& t) { return t.defined() ? t.contiguous() : t; };
        const tensor_list in{contiguous(radiance),       contiguous(features),   contiguous(bandwidth),
                             contiguous(centre),         contiguous(tBandwidth), contiguous(warpedOutput),
                             contiguous(warpedFeatures), contiguous(warpedValid)};
        const Shape s = shapeOf(in[0], in[1]);
        at::Tensor out = at::empty_like(in[0]);
        at::Tensor denominator = at::empty_like(in[3]);
        const std::vector<Tap> spatial = spatialTaps(int(tapSize), int(dilation));
        AT_DISPATCH_FLOATING_TYPES(in[0].scalar_type(), "fusedAffinityFilter", [&] {
            forEachRow<scalar_t>(s, [&](int b, int y, RowScratch<scalar_t>& scratch) {
                forwardRow(elementAt<scalar_t>(in, b), s, spatial, y, mutableElementOf<scalar_t>(out, b),
                           mutableElementOf<scalar_t>(denominator, b), scratch);
            });
        });
        tensor_list saved = in;
        saved.push_back(out);
        saved.push_back(denominator);
        ctx->save_for_backward(saved);
        ctx->saved_data["tapSize"] = tapSize;
        ctx->saved_data["dilation"] = dilation;
        return out;
    }

    static tensor_list backward(AutogradContext* ctx, tensor_list outputGradients) {
        const tensor_list saved = ctx->get_saved_variables();
        const tensor_list in(saved.begin(), saved.begin() + 8);
        const at::Tensor& out = saved[8];
        const at::Tensor& denominator = saved[9];
        const at::Tensor gN = (outputGradients[0] / denominator).contiguous();
        const at::Tensor gD = (-(gN * out).sum(1, true)).contiguous();
        const Shape s = shapeOf(in[0], in[1]);
        auto zerosLike = [](const at::Tensor& t) { return present(t) ? at::zeros_like(t) : at::Tensor(); };
        tensor_list grads{at::empty_like(in[0]), zerosLike(in[1]), zerosLike(in[2]), at::empty_like(in[3]),
                          zerosLike(in[4]),      zerosLike(in[5]), zerosLike(in[6])};
        const std::vector<Tap> spatial =
            spatialTaps(int(ctx->saved_data["tapSize"].toInt()), int(ctx->saved_data["dilation"].toInt()));
        AT_DISPATCH_FLOATING_TYPES(in[0].scalar_type(), "fusedAffinityFilterBackward", [&] {
            forEachRow<scalar_t>(s, [&](int b, int y, RowScratch<scalar_t>& scratch) {
                const Gradients<scalar_t> g{
                    mutableElementOf<scalar_t>(grads[0], b), mutableElementOf<scalar_t>(grads[1], b),
                    mutableElementOf<scalar_t>(grads[2], b), mutableElementOf<scalar_t>(grads[3], b),
                    mutableElementOf<scalar_t>(grads[4], b), mutableElementOf<scalar_t>(grads[5], b),
                    mutableElementOf<scalar_t>(grads[6], b)};
                backwardRow(elementAt<scalar_t>(in, b), s, spatial, elementOf<scalar_t>(gN, b),
                            elementOf<scalar_t>(gD, b), y, g, scratch);
            });
        });
        // The validity, tap size and dilation get none.
        grads.insert(grads.end(), {at::Tensor(), at::Tensor(), at::Tensor()});
        return grads;
    }
};

void checkMatches(const at::Tensor& tensor, const at::Tensor& radiance, std::int64_t channels, const char* what) {
    if (!tensor.defined()) return;
    if (tensor.dim() != 4 || tensor.size(0) != radiance.size(0) || tensor.size(1) != channels ||
        tensor.size(2) != radiance.size(2) || tensor.size(3) != radiance.size(3) ||
        tensor.scalar_type() != radiance.scalar_type() || tensor.device() != radiance.device())
        throw Error(std::string("affinity filter: ") + what +
                    " does not match the filtered signal's batch, size, dtype or device");
}

}  // namespace

bool fusedAffinityFilterApplies(const at::Tensor& radiance) {
    return radiance.device().is_cpu() &&
           (radiance.scalar_type() == at::kFloat || radiance.scalar_type() == at::kDouble);
}

at::Tensor fusedAffinityFilter(const at::Tensor& radiance, const KernelParams& kernel, int tapSize, int dilation,
                               const TemporalTaps* temporal) {
    if (tapSize < 1 || tapSize % 2 == 0)
        throw Error("affinity filter: tap size " + std::to_string(tapSize) + " is not odd");
    if (dilation < 1) throw Error("affinity filter: dilation " + std::to_string(dilation) + " is below 1");
    if (radiance.dim() != 4) throw Error("affinity filter: the filtered signal must be [B, C, H, W]");
    if (!kernel.features.defined() || kernel.features.dim() != 4)
        throw Error("affinity filter: the features must be [B, F, H, W]");
    const std::int64_t F = kernel.features.size(1), C = radiance.size(1);
    checkMatches(kernel.features, radiance, F, "the features");
    checkMatches(kernel.bandwidth, radiance, 1, "the bandwidth");
    checkMatches(kernel.centre, radiance, 1, "the centre weight");
    if (!kernel.bandwidth.defined() || !kernel.centre.defined())
        throw Error("affinity filter: the bandwidth and centre weight are missing");
    at::Tensor tBandwidth, warpedOutput, warpedFeatures, warpedValid;
    if (temporal) {
        checkMatches(temporal->bandwidth, radiance, 1, "the temporal bandwidth");
        checkMatches(temporal->output, radiance, C, "the warped output");
        checkMatches(temporal->features, radiance, F, "the warped features");
        checkMatches(temporal->valid, radiance, 1, "the warped validity");
        if (!temporal->bandwidth.defined() || !temporal->output.defined() || !temporal->features.defined() ||
            !temporal->valid.defined())
            throw Error("affinity filter: a temporal tap input is missing");
        tBandwidth = temporal->bandwidth;
        warpedOutput = temporal->output;
        warpedFeatures = temporal->features;
        warpedValid = temporal->valid.detach();
    }
    return FusedAffinityFilter::apply(radiance, kernel.features, kernel.bandwidth, kernel.centre,
                                      absentAsEmpty(tBandwidth, radiance), absentAsEmpty(warpedOutput, radiance),
                                      absentAsEmpty(warpedFeatures, radiance), absentAsEmpty(warpedValid, radiance),
                                      std::int64_t(tapSize), std::int64_t(dilation));
}

}  // namespace affinity::train
