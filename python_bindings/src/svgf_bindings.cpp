// affinity_core._core.Svgf: the SVGF baseline of affinity/svgf.h on frame dicts.
#include <pybind11/pybind11.h>

#include <charconv>
#include <cstdlib>
#include <utility>
#include <vector>

#include "affinity/svgf.h"
#include "frame_convert.h"

namespace py = pybind11;

namespace affinity {
namespace {

// A float setting as the double with its shortest decimal spelling: Python shows 0.2, not
// 0.20000000298023224.
double shown(float value) {
    char text[32];
    const auto end = std::to_chars(text, text + sizeof text - 1, value).ptr;
    *end = '\0';
    return std::strtod(text, nullptr);
}

}  // namespace

void bindSvgf(py::module_& m) {
    const SvgfSettings defaults;
    py::class_<Svgf>(m, "Svgf",
                     "SVGF (Schied et al. 2017), the hand-designed spatio-temporal baseline: albedo demodulation,\n"
                     "reprojected colour and luminance moments, variance-guided a-trous wavelet filter.\n"
                     "Stateful: feed frames in sequence order; reset() at a camera cut. History is dropped\n"
                     "when the frame size changes. Defaults are the paper's; see core/include/affinity/svgf.h.\n"
                     "Raises affinity_core.Error for settings out of range.")
        .def(py::init([](int atrousIterations, int feedbackIteration, double sigmaDepth, double sigmaNormal,
                         double sigmaLuminance, double alphaColor, double alphaMoments, int historyCap,
                         int spatialVarianceFrames, double reprojectDepthTolerance, double reprojectNormalCosine,
                         double albedoEpsilon) {
                 SvgfSettings s;
                 s.atrousIterations = atrousIterations;
                 s.feedbackIteration = feedbackIteration;
                 s.sigmaDepth = float(sigmaDepth);
                 s.sigmaNormal = float(sigmaNormal);
                 s.sigmaLuminance = float(sigmaLuminance);
                 s.alphaColor = float(alphaColor);
                 s.alphaMoments = float(alphaMoments);
                 s.historyCap = historyCap;
                 s.spatialVarianceFrames = spatialVarianceFrames;
                 s.reprojectDepthTolerance = float(reprojectDepthTolerance);
                 s.reprojectNormalCosine = float(reprojectNormalCosine);
                 s.albedoEpsilon = float(albedoEpsilon);
                 return Svgf(s);
             }),
             py::kw_only(), py::arg("atrous_iterations") = defaults.atrousIterations,
             py::arg("feedback_iteration") = defaults.feedbackIteration,
             py::arg("sigma_depth") = shown(defaults.sigmaDepth), py::arg("sigma_normal") = shown(defaults.sigmaNormal),
             py::arg("sigma_luminance") = shown(defaults.sigmaLuminance),
             py::arg("alpha_color") = shown(defaults.alphaColor),
             py::arg("alpha_moments") = shown(defaults.alphaMoments), py::arg("history_cap") = defaults.historyCap,
             py::arg("spatial_variance_frames") = defaults.spatialVarianceFrames,
             py::arg("reproject_depth_tolerance") = shown(defaults.reprojectDepthTolerance),
             py::arg("reproject_normal_cosine") = shown(defaults.reprojectNormalCosine),
             py::arg("albedo_epsilon") = shown(defaults.albedoEpsilon))
        .def(
            "denoise",
            [](Svgf& self, const py::dict& frame) {
                // Read in place (kept alive by `arrays`), as Denoiser.denoise does.
                const FrameArrays arrays = frameArraysFromDict(frame);
                std::vector<float> rgb;
                {
                    py::gil_scoped_release release;
                    rgb = self.denoise(arrays.view);
                }
                return arrayOwning(std::move(rgb), {arrays.view.height, arrays.view.width, 3});
            },
            py::arg("frame"),
            "Filters the next frame (a frame dict); returns float32 (H, W, 3) linear radiance. NaN, Inf\n"
            "and negative radiance read as 0. The GIL is released while filtering.")
        .def("reset", &Svgf::reset, "Forgets the history, as at a camera cut.")
        .def_property_readonly("settings", [](const Svgf& self) {
            const SvgfSettings& s = self.settings();
            py::dict d;
            d["atrous_iterations"] = s.atrousIterations;
            d["feedback_iteration"] = s.feedbackIteration;
            d["sigma_depth"] = shown(s.sigmaDepth);
            d["sigma_normal"] = shown(s.sigmaNormal);
            d["sigma_luminance"] = shown(s.sigmaLuminance);
            d["alpha_color"] = shown(s.alphaColor);
            d["alpha_moments"] = shown(s.alphaMoments);
            d["history_cap"] = s.historyCap;
            d["spatial_variance_frames"] = s.spatialVarianceFrames;
            d["reproject_depth_tolerance"] = shown(s.reprojectDepthTolerance);
            d["reproject_normal_cosine"] = shown(s.reprojectNormalCosine);
            d["albedo_epsilon"] = shown(s.albedoEpsilon);
            return d;
        });
}

}  // namespace affinity
