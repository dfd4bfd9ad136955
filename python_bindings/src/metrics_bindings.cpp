// affinity_core._core metrics: the C++ error metrics of affinity/metrics.h on numpy images. The
// documented API is python_bindings/affinity_core/metrics.py.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <string>

#include "affinity/metrics.h"

namespace py = pybind11;

namespace affinity {
namespace {

// Any float array (float64 and strided ones are converted), read as C-contiguous float32.
using Image = py::array_t<float, py::array::c_style | py::array::forcecast>;

std::string shapeText(const Image& array) {
    std::string text = "(";
    for (py::ssize_t d = 0; d < array.ndim(); ++d) text += (d ? ", " : "") + std::to_string(array.shape(d));
    return text + (array.ndim() == 1 ? ",)" : ")");
}

bool sameShape(const Image& a, const Image& b) {
    if (a.ndim() != b.ndim()) return false;
    for (py::ssize_t d = 0; d < a.ndim(); ++d)
        if (a.shape(d) != b.shape(d)) return false;
    return true;
}

void requireSameShape(const Image& image, const Image& reference) {
    if (!sameShape(image, reference))
        throw py::value_error("image has shape " + shapeText(image) + " but reference has shape " +
                              shapeText(reference));
}

// (H, W, C) with the given C.
void requireImage(const Image& array, const char* name, py::ssize_t channels) {
    if (array.ndim() != 3 || array.shape(2) != channels)
        throw py::value_error(std::string(name) + " has shape " + shapeText(array) + ", expected (H, W, " +
                              std::to_string(channels) + ")");
}

template <double (*metric)(const float*, const float*, std::size_t)>
double pairMetric(const Image& image, const Image& reference) {
    requireSameShape(image, reference);
    return metric(image.data(), reference.data(), std::size_t(image.size()));
}

// `array` is (h, w, channels) float32.
void requireSize(const Image& array, const char* name, py::ssize_t channels, py::ssize_t h, py::ssize_t w) {
    requireImage(array, name, channels);
    if (array.shape(0) != h || array.shape(1) != w)
        throw py::value_error(std::string(name) + " has shape " + shapeText(array) + ", expected (" +
                              std::to_string(h) + ", " + std::to_string(w) + ", " + std::to_string(channels) + ")");
}

// The motion (h, w, 2) and valid (h, w) maps of the temporal metrics.
void requireMotionAndValid(const Image& motion, const Image& valid, py::ssize_t h, py::ssize_t w) {
    requireSize(motion, "motion", 2, h, w);
    if (valid.ndim() != 2 || valid.shape(0) != h || valid.shape(1) != w)
        throw py::value_error("valid has shape " + shapeText(valid) + ", expected (" + std::to_string(h) + ", " +
                              std::to_string(w) + ")");
}

double temporalErrorOf(const Image& output, const Image& previousOutput, const Image& reference,
                       const Image& previousReference, const Image& motion, const Image& valid) {
    requireImage(output, "output", 3);
    const py::ssize_t h = output.shape(0), w = output.shape(1);
    requireSize(previousOutput, "previous_output", 3, h, w);
    requireSize(reference, "reference", 3, h, w);
    requireSize(previousReference, "previous_reference", 3, h, w);
    requireMotionAndValid(motion, valid, h, w);
    if (h > 1 << 30 || w > 1 << 30) throw py::value_error("output is too large");
    return temporalError(output.data(), previousOutput.data(), reference.data(), previousReference.data(),
                         motion.data(), valid.data(), int(w), int(h));
}

double warpingErrorOf(const Image& image, const Image& previousImage, const Image& motion, const Image& valid) {
    requireImage(image, "image", 3);
    const py::ssize_t h = image.shape(0), w = image.shape(1);
    requireSize(previousImage, "previous_image", 3, h, w);
    requireMotionAndValid(motion, valid, h, w);
    if (h > 1 << 30 || w > 1 << 30) throw py::value_error("image is too large");
    return warpingError(image.data(), previousImage.data(), motion.data(), valid.data(), int(w), int(h));
}

}  // namespace

void bindMetrics(py::module_& m) {
    m.def("smape", &pairMetric<smape>, py::arg("image"), py::arg("reference"),
          "mean |a - b| / (|a| + |b| + 0.01) over every value (see affinity_core.metrics.smape).");
    m.def("relmse", &pairMetric<relativeMse>, py::arg("image"), py::arg("reference"),
          "0.5 * mean (a - b)^2 / (b^2 + 0.01) (see affinity_core.metrics.relmse).");
    m.def("psnr", &pairMetric<tonemappedPsnr>, py::arg("image"), py::arg("reference"),
          "PSNR in dB after x / (1 + x) tone mapping (see affinity_core.metrics.psnr).");
    m.def("temporal_error", &temporalErrorOf, py::arg("output"), py::arg("previous_output"), py::arg("reference"),
          py::arg("previous_reference"), py::arg("motion"), py::arg("valid"),
          "Flicker relative to the reference's own change (see affinity_core.metrics.temporal_error).");
    m.def("warping_error", &warpingErrorOf, py::arg("image"), py::arg("previous_image"), py::arg("motion"),
          py::arg("valid"), "Warping error of Lai et al. 2018 (see affinity_core.metrics.warping_error).");
}

}  // namespace affinity
