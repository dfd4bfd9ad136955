#include "fused_warps.h"

#include <ATen/ATen.h>
#include <ATen/Dispatch.h>
#include <ATen/Parallel.h>
#include <torch/autograd.h>

#include <algorithm>
#include <cmath>

#include "affinity/error.h"

namespace affinity::train {
namespace {

using torch::autograd::AutogradContext;
using torch::autograd::tensor_list;

// Where pixel `pixel` looks along one axis, clamped to [0, size - 1]; NaN motion reads as 0
// (as in warpTargets; infinite motion clamps like the huge finite value it becomes there).
template <typename T>
T clampedPosition(int pixel, T motion, int size) {
    const T at = T(pixel) + (motion == motion ? motion : T(0));
    return at >= T(0) ? (at <= T(size - 1) ? at : T(size - 1)) : T(0);
}

struct Geometry {
    int batch, channels, height, width;
    std::int64_t plane() const { return std::int64_t(height) * width; }
};

// The bilinear taps of one pixel: indices into a plane and their weights (the ATen form's
// order of operations, so that float results agree to the last bits).
template <typename T>
struct BilinearTaps {
    std::int64_t index[4];  // (y0, x0), (y0, x1), (y1, x0), (y1, x1)
    T fx, fy;
};

template <typename T>
BilinearTaps<T> bilinearTaps(const T* motion, const Geometry& g, int y, int x) {
    const std::int64_t p = std::int64_t(y) * g.width + x;
    const T px = clampedPosition(x, motion[p], g.width), py = clampedPosition(y, motion[g.plane() + p], g.height);
    const T x0f = std::floor(px), y0f = std::floor(py);
    const int x0 = int(x0f), y0 = int(y0f), x1 = std::min(x0 + 1, g.width - 1), y1 = std::min(y0 + 1, g.height - 1);
    return {{std::int64_t(y0) * g.width + x0, std::int64_t(y0) * g.width + x1, std::int64_t(y1) * g.width + x0,
             std::int64_t(y1) * g.width + x1},
            px - x0f,
            py - y0f};
}

// The 4x4 Catmull-Rom taps of one pixel: row j and column i sit at floor(position) - 1 + j / i.
template <typename T>
struct CatmullRomTaps {
    std::int64_t row[4];  // y * width of each tap row
    int column[4];
    T wx[4], wy[4];
    std::int64_t at(int j, int i) const { return row[j] + column[i]; }
};

template <typename T>
void catmullRomWeights(T t, T w[4]) {
    const T t2 = t * t, t3 = t2 * t;
    w[0] = (-t3 + T(2) * t2 - t) * T(0.5);
    w[1] = (T(3) * t3 - T(5) * t2 + T(2)) * T(0.5);
    w[2] = (T(-3) * t3 + T(4) * t2 + t) * T(0.5);
    w[3] = (t3 - t2) * T(0.5);
}

template <typename T>
CatmullRomTaps<T> catmullRomTaps(const T* motion, const Geometry& g, int y, int x) {
    const std::int64_t p = std::int64_t(y) * g.width + x;
    const T px = clampedPosition(x, motion[p], g.width), py = clampedPosition(y, motion[g.plane() + p], g.height);
    const T x0 = std::floor(px), y0 = std::floor(py);
    CatmullRomTaps<T> taps;
    catmullRomWeights(px - x0, taps.wx);
    catmullRomWeights(py - y0, taps.wy);
    for (int k = 0; k < 4; ++k) {
        taps.column[k] = std::clamp(int(x0) + k - 1, 0, g.width - 1);
        taps.row[k] = std::int64_t(std::clamp(int(y0) + k - 1, 0, g.height - 1)) * g.width;
    }
    return taps;
}

// The unclamped spline and the range of the four nearest taps (p00, p01, p10, p11).
template <typename T>
struct CatmullRomValue {
    T sum, nearest[4];
    T low() const { return std::min(std::min(nearest[0], nearest[1]), std::min(nearest[2], nearest[3])); }
    T high() const { return std::max(std::max(nearest[0], nearest[1]), std::max(nearest[2], nearest[3])); }
};

template <typename T>
CatmullRomValue<T> catmullRomValue(const T* plane, const CatmullRomTaps<T>& taps) {
    CatmullRomValue<T> v;
    for (int j = 0; j < 4; ++j) {
        T row = plane[taps.at(j, 0)] * taps.wx[0];
        for (int i = 1; i < 4; ++i) row = row + plane[taps.at(j, i)] * taps.wx[i];
        v.sum = j == 0 ? row * taps.wy[0] : v.sum + row * taps.wy[j];
    }
    v.nearest[0] = plane[taps.at(1, 1)];
    v.nearest[1] = plane[taps.at(1, 2)];
    v.nearest[2] = plane[taps.at(2, 1)];
    v.nearest[3] = plane[taps.at(2, 2)];
    return v;
}

// ATen's minimum / maximum backward: the gradient goes to the smaller (larger) operand, split
// in half on a tie.
template <typename T>
void splitGradient(T a, T b, bool toSmaller, T gradient, T& ga, T& gb) {
    if (a == b) {
        ga = gb = gradient / T(2);
    } else {
        const bool first = toSmaller ? a < b : a > b;
        ga = first ? gradient : T(0);
        gb = first ? T(0) : gradient;
    }
}

// The gradient of min / max of the four nearest taps, added to those taps.
template <typename T>
void addRangeGradient(const CatmullRomValue<T>& v, const CatmullRomTaps<T>& taps, bool low, T gradient, T* out) {
    const T* n = v.nearest;
    const T pair0 = low ? std::min(n[0], n[1]) : std::max(n[0], n[1]);
    const T pair1 = low ? std::min(n[2], n[3]) : std::max(n[2], n[3]);
    T g0, g1, g00, g01, g10, g11;
    splitGradient(pair0, pair1, low, gradient, g0, g1);
    splitGradient(n[0], n[1], low, g0, g00, g01);
    splitGradient(n[2], n[3], low, g1, g10, g11);
    out[taps.at(1, 1)] += g00;
    out[taps.at(1, 2)] += g01;
    out[taps.at(2, 1)] += g10;
    out[taps.at(2, 2)] += g11;
}

Geometry geometryOf(const at::Tensor& previous) {
    return {int(previous.size(0)), int(previous.size(1)), int(previous.size(2)), int(previous.size(3))};
}

// Runs fn(batch element, channel) over every plane in parallel: a plane's backward scatters
// only into its own plane, so planes need no synchronisation.
template <typename Fn>
void forEachPlane(const Geometry& g, Fn&& fn) {
    at::parallel_for(0, std::int64_t(g.batch) * g.channels, 1, [&](std::int64_t begin, std::int64_t end) {
        for (std::int64_t i = begin; i < end; ++i) fn(int(i / g.channels), int(i % g.channels));
    });
}

enum class Kind { Bilinear, CatmullRom };

template <Kind kind>
struct FusedWarp : public torch::autograd::Function<FusedWarp<kind>> {
    static at::Tensor forward(AutogradContext* ctx, const at::Tensor& previousIn, const at::Tensor& motionIn) {
        const at::Tensor previous = previousIn.contiguous(), motion = motionIn.contiguous();
        const Geometry g = geometryOf(previous);
        at::Tensor out = at::empty_like(previous);
        AT_DISPATCH_FLOATING_TYPES(previous.scalar_type(), "fusedWarp", [&] {
            using T = scalar_t;
            forEachPlane(g, [&](int b, int c) {
                const T* m = motion.data_ptr<T>() + std::int64_t(b) * 2 * g.plane();
                const T* in = previous.data_ptr<T>() + (std::int64_t(b) * g.channels + c) * g.plane();
                T* o = out.data_ptr<T>() + (std::int64_t(b) * g.channels + c) * g.plane();
                for (int y = 0; y < g.height; ++y)
                    for (int x = 0; x < g.width; ++x) {
                        T value;
                        if constexpr (kind == Kind::Bilinear) {
                            const BilinearTaps<T> t = bilinearTaps(m, g, y, x);
                            const T top = in[t.index[0]] * (T(1) - t.fx) + in[t.index[1]] * t.fx;
                            const T bottom = in[t.index[2]] * (T(1) - t.fx) + in[t.index[3]] * t.fx;
                            value = top * (T(1) - t.fy) + bottom * t.fy;
                        } else {
                            const CatmullRomValue<T> v = catmullRomValue(in, catmullRomTaps(m, g, y, x));
                            value = std::min(std::max(v.sum, v.low()), v.high());
                        }
                        o[std::int64_t(y) * g.width + x] = value;
                    }
            });
        });
        ctx->save_for_backward({previous, motion});
        return out;
    }

    static tensor_list backward(AutogradContext* ctx, tensor_list outputGradients) {
        const tensor_list saved = ctx->get_saved_variables();
        const at::Tensor& previous = saved[0];
        const at::Tensor& motion = saved[1];
        const at::Tensor gradient = outputGradients[0].contiguous();
        const Geometry g = geometryOf(previous);
        at::Tensor result = at::zeros_like(previous);
        AT_DISPATCH_FLOATING_TYPES(previous.scalar_type(), "fusedWarpBackward", [&] {
            using T = scalar_t;
            forEachPlane(g, [&](int b, int c) {
                const std::int64_t offset = (std::int64_t(b) * g.channels + c) * g.plane();
                const T* m = motion.data_ptr<T>() + std::int64_t(b) * 2 * g.plane();
                const T* in = previous.data_ptr<T>() + offset;
                const T* go = gradient.data_ptr<T>() + offset;
                T* gi = result.data_ptr<T>() + offset;
                for (int y = 0; y < g.height; ++y)
                    for (int x = 0; x < g.width; ++x) {
                        const T d = go[std::int64_t(y) * g.width + x];
                        if constexpr (kind == Kind::Bilinear) {
                            const BilinearTaps<T> t = bilinearTaps(m, g, y, x);
                            gi[t.index[0]] += d * (T(1) - t.fx) * (T(1) - t.fy);
                            gi[t.index[1]] += d * t.fx * (T(1) - t.fy);
                            gi[t.index[2]] += d * (T(1) - t.fx) * t.fy;
                            gi[t.index[3]] += d * t.fx * t.fy;
                        } else {
                            // clamp(sum, low, high): the gradient goes to low below the range,
                            // to high above it, else through the spline to its 16 taps.
                            const CatmullRomTaps<T> t = catmullRomTaps(m, g, y, x);
                            const CatmullRomValue<T> v = catmullRomValue(in, t);
                            if (!(v.sum >= v.low())) {
                                addRangeGradient(v, t, true, d, gi);
                            } else if (!(v.sum <= v.high())) {
                                addRangeGradient(v, t, false, d, gi);
                            } else {
                                for (int j = 0; j < 4; ++j)
                                    for (int i = 0; i < 4; ++i) gi[t.at(j, i)] += d * t.wy[j] * t.wx[i];
                            }
                        }
                    }
            });
        });
        return {result, at::Tensor()};
    }
};

}  // namespace

bool fusedWarpApplies(const at::Tensor& previous, const at::Tensor& motion) {
    return previous.device().is_cpu() && motion.device().is_cpu() && !motion.requires_grad() &&
           (previous.scalar_type() == at::kFloat || previous.scalar_type() == at::kDouble) &&
           motion.scalar_type() == previous.scalar_type() && previous.dim() == 4 && motion.dim() == 4 &&
           motion.size(0) == previous.size(0) && motion.size(1) == 2 && motion.size(2) == previous.size(2) &&
           motion.size(3) == previous.size(3);
}

at::Tensor fusedWarpBilinear(const at::Tensor& previous, const at::Tensor& motion) {
    if (!fusedWarpApplies(previous, motion))
        throw Error("fused warp: needs CPU float or double [B, C, H, W] and [B, 2, H, W] motion without grad");
    return FusedWarp<Kind::Bilinear>::apply(previous, motion);
}

at::Tensor fusedWarpCatmullRom(const at::Tensor& previous, const at::Tensor& motion) {
    if (!fusedWarpApplies(previous, motion))
        throw Error("fused warp: needs CPU float or double [B, C, H, W] and [B, 2, H, W] motion without grad");
    return FusedWarp<Kind::CatmullRom>::apply(previous, motion);
}

}  // namespace affinity::train
