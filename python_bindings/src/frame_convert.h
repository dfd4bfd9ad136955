#pragma once
// Frames between Python dicts of numpy arrays and C++, shared by the binding files; defined in
// bindings.cpp. The dict layout is documented in python_bindings/affinity_core/__init__.py.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <vector>

#include "affinity/frame.h"

namespace affinity {

// A numpy array that takes over a vector's storage instead of copying it.
pybind11::array_t<float> arrayOwning(std::vector<float>&& values, std::vector<pybind11::ssize_t> shape);

// A frame dict's arrays, checked (C-contiguous float32: converted only if they are not), and a
// view of them that stays valid while this object lives.
struct FrameArrays {
    pybind11::array_t<float, pybind11::array::c_style> samples, motion, valid, reference;
    SampleFrameView view;
};
// Raises TypeError / ValueError / KeyError naming the bad key.
FrameArrays frameArraysFromDict(const pybind11::dict& dict);

}  // namespace affinity
