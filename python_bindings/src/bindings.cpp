// affinity_core._core: frames as dicts of numpy arrays. The public, documented API is the pure
// Python package python_bindings/affinity_core/__init__.py, which re-exports these.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "affinity/denoise_file.h"
#include "affinity/denoiser.h"
#include "affinity/error.h"
#include "affinity/features.h"
#include "affinity/frame.h"
#include "affinity/frame_io.h"
#include "affinity/model.h"
#include "frame_convert.h"
#include "pipeline/ablation.h"

namespace py = pybind11;

namespace affinity {

void bindMetrics(py::module_& m);  // metrics_bindings.cpp
void bindSvgf(py::module_& m);     // svgf_bindings.cpp

namespace {

using FloatArray = py::array_t<float, py::array::c_style>;

// What a Python signal handler raised (KeyboardInterrupt at Ctrl-C) during a native call on this
// thread, kept from the denoiser's interrupt check until the call has unwound.
thread_local std::optional<py::error_already_set> raisedDuringCall;

// The denoiser's interrupt check: runs the Python signal handlers (only the main thread has any
// to run) with the GIL taken for the moment. Without it, Ctrl-C waited for the whole frame.
bool pythonSignalRaised() {
    py::gil_scoped_acquire gil;
    if (PyErr_CheckSignals() == 0) return false;
    raisedDuringCall.emplace();  // fetches the handler's exception, clearing it for now
    return true;
}

// Runs a native denoiser call with the GIL released; if a signal handler's exception stopped
// it, that exception (KeyboardInterrupt) is what Python gets.
template <typename Call>
auto interruptible(Call&& call) {
    try {
        py::gil_scoped_release release;
        return call();
    } catch (const Interrupted&) {
        if (!raisedDuringCall) throw;
        py::error_already_set raised = std::move(*raisedDuringCall);
        raisedDuringCall.reset();
        throw raised;
    }
}

}  // namespace

// --- frame -> Python ------------------------------------------------------------------------

// Declared in frame_convert.h, as frameArraysFromDict below.
py::array_t<float> arrayOwning(std::vector<float>&& values, std::vector<py::ssize_t> shape) {
    auto owner = std::make_unique<std::vector<float>>(std::move(values));
    float* data = owner->data();
    py::capsule base(owner.get(), [](void* p) { delete static_cast<std::vector<float>*>(p); });
    owner.release();  // the capsule owns it now
    return py::array_t<float>(std::move(shape), data, base);
}

namespace {

py::array_t<float> matrixArray(const Matrix4& m) { return arrayOwning(std::vector<float>(m.begin(), m.end()), {4, 4}); }

// Scene names are bytes in the file; surrogateescape keeps any non-UTF-8 name round-tripping.
py::str decodeName(const std::string& name) {
    PyObject* text = PyUnicode_DecodeUTF8(name.data(), py::ssize_t(name.size()), "surrogateescape");
    if (text == nullptr) throw py::error_already_set();
    return py::reinterpret_steal<py::str>(text);
}

std::string encodeName(const py::handle& value, const std::string& key) {
    if (!py::isinstance<py::str>(value)) {
        throw py::type_error(key + " must be a str, got " + std::string(py::str(py::type::of(value).attr("__name__"))));
    }
    PyObject* bytes = PyUnicode_AsEncodedString(value.ptr(), "utf-8", "surrogateescape");
    if (bytes == nullptr) throw py::error_already_set();
    return std::string(py::reinterpret_steal<py::bytes>(bytes));
}

py::dict frameToDict(SampleFrame&& frame) {
    const py::ssize_t h = frame.height(), w = frame.width(), spp = frame.spp();
    const bool hasReference = frame.hasReference();
    py::dict info;
    info["scene_name"] = decodeName(frame.info.sceneName);
    info["frame_index"] = frame.info.frameIndex;
    info["reference_spp"] = frame.info.referenceSpp;
    info["seed"] = py::int_(frame.info.seed);
    info["world_to_camera"] = matrixArray(frame.info.worldToCamera);
    info["camera_to_clip"] = matrixArray(frame.info.cameraToClip);

    py::dict result;
    // None for a frame whose samples were read elsewhere (Denoiser.denoise_file).
    result["samples"] = frame.samples().empty()
                            ? py::object(py::none())
                            : py::object(arrayOwning(std::move(frame.samples()), {h, w, spp, kFeatureCount}));
    result["motion"] = arrayOwning(std::move(frame.motion()), {h, w, 2});
    result["valid"] = arrayOwning(std::move(frame.valid()), {h, w});
    result["reference"] =
        hasReference ? py::object(arrayOwning(std::move(frame.reference()), {h, w, 3})) : py::object(py::none());
    result["info"] = std::move(info);
    return result;
}

// --- Python -> frame ------------------------------------------------------------------------

std::string shapeText(const py::array& array) {
    std::string text = "(";
    for (py::ssize_t d = 0; d < array.ndim(); ++d) {
        if (d > 0) text += ", ";
        text += std::to_string(array.shape(d));
    }
    return text + (array.ndim() == 1 ? ",)" : ")");
}

// A C-contiguous float32 view (copied only when the input is strided) after checking the
// dtype and shape; expected dims of -1 are free. `shapeName` spells the expected shape.
FloatArray floatArray(const py::handle& value, const std::string& key, const std::vector<py::ssize_t>& expected,
                      const std::string& shapeName) {
    if (!py::isinstance<py::array>(value)) {
        throw py::type_error(key + " must be a numpy float32 array, got " +
                             std::string(py::str(py::type::of(value).attr("__name__"))));
    }
    const auto array = py::reinterpret_borrow<py::array>(value);
    if (!py::isinstance<py::array_t<float>>(array)) {
        throw py::type_error(key + " must have dtype float32, got " + std::string(py::str(array.dtype())));
    }
    bool matches = array.ndim() == py::ssize_t(expected.size());
    for (std::size_t d = 0; matches && d < expected.size(); ++d) {
        matches = expected[d] < 0 || array.shape(py::ssize_t(d)) == expected[d];
    }
    if (!matches) {
        throw py::value_error(key + " has shape " + shapeText(array) + ", expected " + shapeName);
    }
    return FloatArray::ensure(array);
}

void copyInto(std::vector<float>& destination, const FloatArray& source) {
    std::memcpy(destination.data(), source.data(), destination.size() * sizeof(float));
}

long long integer(const py::handle& value, const std::string& key, long long low, long long high) {
    // operator.index semantics: Python and numpy integers pass, floats and bools do not.
    if (py::isinstance<py::bool_>(value) || !PyIndex_Check(value.ptr())) {
        throw py::type_error(key + " must be an int, got " +
                             std::string(py::str(py::type::of(value).attr("__name__"))));
    }
    const auto number = py::reinterpret_steal<py::object>(PyNumber_Index(value.ptr()));
    if (!number) throw py::error_already_set();
    int overflow = 0;
    const long long result = PyLong_AsLongLongAndOverflow(number.ptr(), &overflow);
    if (result == -1 && PyErr_Occurred()) throw py::error_already_set();
    if (overflow != 0 || result < low || result > high) {
        throw py::value_error(key + " is " + std::string(py::str(number)) + ", expected " + std::to_string(low) + ".." +
                              std::to_string(high));
    }
    return result;
}

std::uint64_t seedValue(const py::handle& value, const std::string& key) {
    if (py::isinstance<py::bool_>(value) || !PyIndex_Check(value.ptr())) {
        throw py::type_error(key + " must be an int, got " +
                             std::string(py::str(py::type::of(value).attr("__name__"))));
    }
    const auto number = py::reinterpret_steal<py::object>(PyNumber_Index(value.ptr()));
    if (!number) throw py::error_already_set();
    const unsigned long long seed = PyLong_AsUnsignedLongLong(number.ptr());
    if (seed == static_cast<unsigned long long>(-1) && PyErr_Occurred()) {
        PyErr_Clear();
        throw py::value_error(key + " is " + std::string(py::str(number)) + ", expected an integer in [0, 2**64)");
    }
    return seed;
}

Matrix4 matrixValue(const py::handle& value, const std::string& key) {
    const auto array = floatArray(value, key, {4, 4}, "(4, 4)");
    Matrix4 m{};
    std::memcpy(m.data(), array.data(), sizeof m);
    return m;
}

void checkKeys(const py::dict& dict, const std::string& what, const std::vector<std::string>& allowed) {
    for (const auto& item : dict) {
        const std::string key = py::str(item.first);
        bool known = false;
        for (const std::string& name : allowed) known = known || key == name;
        if (!known) {
            std::string list;
            for (const std::string& name : allowed) {
                list += (list.empty() ? "'" : ", '") + name + "'";
            }
            throw py::value_error(what + " has unknown key '" + key + "' (expected " + list + ")");
        }
    }
}

py::object requireKey(const py::dict& dict, const std::string& what, const char* key) {
    if (!dict.contains(key)) throw py::key_error(what + " is missing '" + key + "'");
    return dict[key];
}

FrameInfo infoFromDict(const py::handle& value) {
    if (!py::isinstance<py::dict>(value)) {
        throw py::type_error("frame['info'] must be a dict, got " +
                             std::string(py::str(py::type::of(value).attr("__name__"))));
    }
    const auto dict = py::reinterpret_borrow<py::dict>(value);
    const std::string what = "frame['info']";
    checkKeys(dict, what, {"scene_name", "frame_index", "reference_spp", "seed", "world_to_camera", "camera_to_clip"});
    const auto key = [&](const char* name) { return what + "['" + name + "']"; };
    FrameInfo info;
    info.sceneName = encodeName(requireKey(dict, what, "scene_name"), key("scene_name"));
    constexpr long long kIntMax = 2147483647;
    info.frameIndex = int(integer(requireKey(dict, what, "frame_index"), key("frame_index"), 0, kIntMax));
    info.referenceSpp = int(integer(requireKey(dict, what, "reference_spp"), key("reference_spp"), 0, kIntMax));
    info.seed = seedValue(requireKey(dict, what, "seed"), key("seed"));
    info.worldToCamera = matrixValue(requireKey(dict, what, "world_to_camera"), key("world_to_camera"));
    info.cameraToClip = matrixValue(requireKey(dict, what, "camera_to_clip"), key("camera_to_clip"));
    return info;
}

}  // namespace

FrameArrays frameArraysFromDict(const py::dict& dict) {
    const std::string what = "frame";
    checkKeys(dict, what, {"samples", "motion", "valid", "reference", "info"});
    const auto samples =
        floatArray(requireKey(dict, what, "samples"), "frame['samples']", {-1, -1, -1, kFeatureCount}, "(H, W, S, 18)");
    const py::ssize_t h = samples.shape(0), w = samples.shape(1), spp = samples.shape(2);
    if (h < 1 || w < 1 || spp < 1 || spp > SampleFrame::kMaxSpp || h > 1 << 30 || w > 1 << 30) {
        throw py::value_error("frame['samples'] has shape " + shapeText(samples) + ", expected H, W >= 1 and S in 1.." +
                              std::to_string(SampleFrame::kMaxSpp));
    }
    const std::string hw = std::to_string(h) + ", " + std::to_string(w);
    const auto motion = floatArray(requireKey(dict, what, "motion"), "frame['motion']", {h, w, 2}, "(" + hw + ", 2)");
    const auto valid = floatArray(requireKey(dict, what, "valid"), "frame['valid']", {h, w}, "(" + hw + ")");
    const py::object referenceValue =
        dict.contains("reference") ? py::object(dict["reference"]) : py::object(py::none());
    const bool hasReference = !referenceValue.is_none();
    FloatArray reference;
    if (hasReference) {
        reference = floatArray(referenceValue, "frame['reference']", {h, w, 3}, "(" + hw + ", 3)");
    }
    FrameArrays arrays{samples, motion, valid, reference, {}};
    arrays.view = SampleFrameView{int(w),
                                  int(h),
                                  int(spp),
                                  arrays.samples.data(),
                                  arrays.motion.data(),
                                  arrays.valid.data(),
                                  infoFromDict(requireKey(dict, what, "info"))};
    return arrays;
}

namespace {

// A frame dict as a SampleFrame (a copy, for writing it); raises as frameArraysFromDict.
SampleFrame frameFromDict(const py::dict& dict) {
    const FrameArrays arrays = frameArraysFromDict(dict);
    const SampleFrameView& view = arrays.view;
    SampleFrame frame(view.width, view.height, view.spp, arrays.reference.size() > 0);
    copyInto(frame.samples(), arrays.samples);
    copyInto(frame.motion(), arrays.motion);
    copyInto(frame.valid(), arrays.valid);
    if (frame.hasReference()) copyInto(frame.reference(), arrays.reference);
    frame.info = view.info;
    return frame;
}

// What Denoiser.last_report holds (see python_bindings/affinity_core/__init__.py).
py::dict reportDict(const DenoiseReport& report) {
    py::dict info;
    info["invalid_radiance"] = report.invalidRadiance;
    info["used_history"] = report.usedHistory;
    info["reset_reason"] = report.resetReason;
    info["exposure"] = report.exposure;
    py::dict stages;
    for (const auto& [stage, ms] : report.stageMilliseconds) stages[py::str(stage)] = ms;
    info["stage_ms"] = stages;
    info["buffer_bytes"] = report.bufferBytes;
    return info;
}

ExrCompression compressionFromName(const std::string& name) {
    if (name == "none") return ExrCompression::None;
    if (name == "zip") return ExrCompression::Zip;
    if (name == "piz") return ExrCompression::Piz;
    throw py::value_error("compression is '" + name + "', expected 'none', 'zip' or 'piz'");
}

}  // namespace
}  // namespace affinity

PYBIND11_MODULE(_core, m) {
    using namespace affinity;
    m.doc() = "Native part of the affinity_core package; use the `affinity_core` package instead.";

    py::register_exception<Error>(m, "Error", PyExc_RuntimeError);

    py::list names;
    for (int c = 0; c < kFeatureCount; ++c) names.append(featureChannelName(c));
    m.attr("FEATURE_NAMES") = names;
    m.attr("FEATURE_COUNT") = kFeatureCount;
    m.attr("MAX_SPP") = SampleFrame::kMaxSpp;
    bindMetrics(m);
    bindSvgf(m);

    m.def(
        "read_frame",
        [](const std::filesystem::path& path) {
            SampleFrame frame;
            {
                py::gil_scoped_release release;
                frame = readFrame(path.string());
            }
            return frameToDict(std::move(frame));
        },
        py::arg("path"), "Reads a frame file into a dict of numpy arrays (see affinity_core.read_frame).");

    m.def(
        "write_frame",
        [](const std::filesystem::path& path, const py::dict& frame, const std::string& compression) {
            const ExrCompression mode = compressionFromName(compression);
            const SampleFrame native = frameFromDict(frame);
            py::gil_scoped_release release;
            writeFrame(path.string(), native, mode);
        },
        py::arg("path"), py::arg("frame"), py::arg("compression") = "piz",
        "Writes a frame dict atomically (see affinity_core.write_frame).");

    m.def("bfloat16_supported", &bfloat16Supported,
          "Whether this CPU can run models with precision='bf16' (AVX512-BF16).");
    m.def("frame_file_name", &frameFileName, py::arg("frame_index"), "'frame_0007.exr' for frame index 7.");
    m.def(
        "list_frame_files", [](const std::filesystem::path& directory) { return listFrameFiles(directory.string()); },
        py::arg("directory"), "Frame files of a sequence folder, in frame order.");

    py::class_<Model>(m, "Model", "A denoising model (weights + structure), see docs/MODEL.md.")
        .def_static(
            "built_in", [](const std::string& precision) { return Model::builtIn(precisionFromName(precision)); },
            py::arg("precision") = "auto",
            "The default model compiled into the library; precision 'auto' (bf16 where "
            "affinity_core.bfloat16_supported(), else fp32), 'fp32' or 'bf16'.")
        .def_static(
            "from_file",
            [](const std::filesystem::path& path, const std::string& precision) {
                return Model::fromFile(path.string(), precisionFromName(precision));
            },
            py::arg("path"), py::arg("precision") = "auto", "Loads a .affw weights file; precision as for built_in.")
        // What it computes in: 'fp32' or 'bf16' ('auto' resolved).
        .def_property_readonly("precision",
                               [](const Model& model) { return std::string(precisionName(model.precision())); })
        .def_property_readonly("source", &Model::source)
        .def_property_readonly("kernels", &Model::kernels)
        .def_property_readonly("affinity_features", &Model::affinityFeatures)
        .def_property_readonly("tap_size", &Model::tapSize)
        .def_property_readonly("light_restoration", &Model::lightRestoration)
        .def_property_readonly("embedding_channels", &Model::embeddingChannels)
        .def_property_readonly("parameter_count", &Model::parameterCount)
        .def("flops_per_pixel", &Model::flopsPerPixel, py::arg("spp"));

    py::class_<Denoiser>(m, "Denoiser", "Stateful sequence denoiser (see affinity_core.Denoiser).")
        .def(py::init([](Model model, bool useHistory, bool temporalKernel, bool allKernels, bool lightRestoration,
                         bool inputFallback, bool peakGuard, bool historyGuard) {
                 // The benchmark's ablations (affinity_core.Denoiser(ablation=...)): internal to the library.
                 Denoiser denoiser = ablatedDenoiser(
                     std::move(model), Ablation{useHistory, temporalKernel, allKernels, lightRestoration, inputFallback,
                                                peakGuard, historyGuard});
                 denoiser.setInterruptCheck(pythonSignalRaised);
                 return denoiser;
             }),
             py::arg("model"), py::kw_only(), py::arg("use_history") = true, py::arg("temporal_kernel") = true,
             py::arg("all_kernels") = true, py::arg("light_restoration") = true, py::arg("input_fallback") = true,
             py::arg("peak_guard") = true, py::arg("history_guard") = true)
        .def(
            "denoise",
            [](Denoiser& self, const py::dict& frame) {
                // The denoiser reads the dict's arrays in place (kept alive by `arrays`).
                const FrameArrays arrays = frameArraysFromDict(frame);
                DenoiseReport report;
                std::vector<float> rgb = interruptible([&] { return self.denoise(arrays.view, &report); });
                return py::make_tuple(arrayOwning(std::move(rgb), {arrays.view.height, arrays.view.width, 3}),
                                      reportDict(report));
            },
            py::arg("frame"))
        .def(
            "denoise_file",
            [](Denoiser& self, const std::filesystem::path& path) {
                if (self.pending().spp > 0)
                    throw py::value_error("denoise_file: " + std::to_string(self.pending().spp) +
                                          " samples added with add_samples() wait for finish_frame()");
                DenoiseReport report;
                DenoisedFile file =
                    interruptible([&] { return denoiseFrameFile(self, path.string(), NoisyMean::Always, &report); });
                const py::ssize_t h = file.frame.height(), w = file.frame.width();
                py::dict result = frameToDict(std::move(file.frame));
                result["noisy"] = arrayOwning(std::move(file.noisy), {h, w, 3});
                return py::make_tuple(arrayOwning(std::move(file.denoised), {h, w, 3}), reportDict(report), result);
            },
            py::arg("path"))
        .def(
            "add_samples",
            [](Denoiser& self, const py::handle& value) {
                // (H, W, S, 18), or (H, W, 18) for one sample; read in place during the call.
                const bool single =
                    py::isinstance<py::array>(value) && py::reinterpret_borrow<py::array>(value).ndim() == 3;
                const auto samples =
                    single ? floatArray(value, "samples", {-1, -1, kFeatureCount}, "(H, W, 18)")
                           : floatArray(value, "samples", {-1, -1, -1, kFeatureCount}, "(H, W, S, 18) or (H, W, 18)");
                const py::ssize_t h = samples.shape(0), w = samples.shape(1), spp = single ? 1 : samples.shape(2);
                if (h < 1 || w < 1 || spp < 1 || h > 1 << 30 || w > 1 << 30 || spp > SampleFrame::kMaxSpp)
                    throw py::value_error("samples has shape " + shapeText(samples) +
                                          ", expected H, W >= 1 and S in 1.." + std::to_string(SampleFrame::kMaxSpp));
                const Denoiser::PendingFrame pending = self.pending();
                if (pending.spp > 0 && (pending.width != w || pending.height != h))
                    throw py::value_error("samples has shape " + shapeText(samples) +
                                          " but the frame's first batch was " + std::to_string(pending.height) + "x" +
                                          std::to_string(pending.width));
                if (pending.spp + spp > SampleFrame::kMaxSpp)
                    throw py::value_error("a frame holds at most " + std::to_string(SampleFrame::kMaxSpp) +
                                          " samples per pixel; " + std::to_string(pending.spp) + " were added");
                py::gil_scoped_release release;
                self.addSamples(int(w), int(h), int(spp), samples.data());
            },
            py::arg("samples"))
        .def(
            "finish_frame",
            [](Denoiser& self, const py::dict& frame) {
                const Denoiser::PendingFrame pending = self.pending();
                if (pending.spp == 0) throw py::value_error("finish_frame: no samples were added with add_samples()");
                const std::string what = "frame";
                checkKeys(frame, what, {"motion", "valid", "reference", "info"});
                const std::string hw = std::to_string(pending.height) + ", " + std::to_string(pending.width);
                const auto motion = floatArray(requireKey(frame, what, "motion"), "frame['motion']",
                                               {pending.height, pending.width, 2}, "(" + hw + ", 2)");
                const auto valid = floatArray(requireKey(frame, what, "valid"), "frame['valid']",
                                              {pending.height, pending.width}, "(" + hw + ")");
                const FrameInfo info = infoFromDict(requireKey(frame, what, "info"));
                DenoiseReport report;
                std::vector<float> rgb =
                    interruptible([&] { return self.finishFrame(motion.data(), valid.data(), info, &report); });
                return py::make_tuple(arrayOwning(std::move(rgb), {pending.height, pending.width, 3}),
                                      reportDict(report));
            },
            py::arg("frame"))
        .def("discard_samples", &Denoiser::discardSamples)
        .def_property_readonly("pending_samples", [](const Denoiser& self) { return self.pending().spp; })
        .def("reset", &Denoiser::reset)
        .def(
            "continues_sequence",
            [](const Denoiser& self, int width, int height, const py::handle& worldToCamera) {
                return self.continuesSequence(width, height, matrixValue(worldToCamera, "world_to_camera"));
            },
            py::arg("width"), py::arg("height"), py::arg("world_to_camera"))
        .def_property_readonly("model", &Denoiser::model);
}
