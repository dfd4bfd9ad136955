// affinity._core.Svgf: the SVGF baseline of affinity/svgf.h on frame dicts.
#include <pybind11/pybind11.h>

#include <utility>
#include <vector>

#include "affinity/svgf.h"
#include "frame_convert.h"

namespace py = pybind11;

namespace affinity {

void bindSvgf(py::module_& m) {
    const SvgfSettings defaults;
    py::class_<Svgf>(m, "Svgf",
                     "SVGF (Schied et al. 2017), the hand-designed spatio-temporal baseline: albedo demodulation,\n"
                     "reprojected colour and luminance moments, variance-guided a-trous wavelet filter.\n"
                     "Stateful: feed frames in sequence order; reset() at a camera cut. History is dropped\n"
                     "when the frame size changes. Defaults are the paper's; see core/include/affinity/svgf.h.\n"
                     "Raises affinity.Error for settings out of range.")
        .def(py::init([](int atrousIterations, int feedbackIteration, float sigmaDepth, float sigmaNormal,
                         float sigmaLuminance, float alphaColor, float alphaMoments, int historyCap,
                         int spatialVarianceFrames, float reprojectDepthTolerance, float reprojectNormalCosine,
                         float albedoEpsilon) {
                 SvgfSettings s;
                 s.atrousIterations = atrousIterations;
                 s.feedbackIteration = feedbackIteration;
                 s.sigmaDepth = sigmaDepth;
                 s.sigmaNormal = sigmaNormal;
                 s.sigmaLuminance = sigmaLuminance;
                 s.alphaColor = alphaColor;
                 s.alphaMoments = alphaMoments;
                 s.historyCap = historyCap;
                 s.spatialVarianceFrames = spatialVarianceFrames;
                 s.reprojectDepthTolerance = reprojectDepthTolerance;
                 s.reprojectNormalCosine = reprojectNormalCosine;
                 s.albedoEpsilon = albedoEpsilon;
                 return Svgf(s);
             }),
             py::kw_only(), py::arg("atrous_iterations") = defaults.atrousIterations,
             py::arg("feedback_iteration") = defaults.feedbackIteration, py::arg("sigma_depth") = defaults.sigmaDepth,
             py::arg("sigma_normal") = defaults.sigmaNormal, py::arg("sigma_luminance") = defaults.sigmaLuminance,
             py::arg("alpha_color") = defaults.alphaColor, py::arg("alpha_moments") = defaults.alphaMoments,
             py::arg("history_cap") = defaults.historyCap,
             py::arg("spatial_variance_frames") = defaults.spatialVarianceFrames,
             py::arg("reproject_depth_tolerance") = defaults.reprojectDepthTolerance,
             py::arg("reproject_normal_cosine") = defaults.reprojectNormalCosine,
             py::arg("albedo_epsilon") = defaults.albedoEpsilon)
        .def(
            "denoise",
            [](Svgf& self, const py::dict& frame) {
                const SampleFrame native = frameFromDict(frame);
                std::vector<float> rgb;
                {
                    py::gil_scoped_release release;
                    rgb = self.denoise(native);
                }
                return arrayOwning(std::move(rgb), {native.height(), native.width(), 3});
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
            d["sigma_depth"] = s.sigmaDepth;
            d["sigma_normal"] = s.sigmaNormal;
            d["sigma_luminance"] = s.sigmaLuminance;
            d["alpha_color"] = s.alphaColor;
            d["alpha_moments"] = s.alphaMoments;
            d["history_cap"] = s.historyCap;
            d["spatial_variance_frames"] = s.spatialVarianceFrames;
            d["reproject_depth_tolerance"] = s.reprojectDepthTolerance;
            d["reproject_normal_cosine"] = s.reprojectNormalCosine;
            d["albedo_epsilon"] = s.albedoEpsilon;
            return d;
        });
}

}  // namespace affinity
