#pragma once
// Plain-C++ entry points into the libtorch model (no torch types here), so that parity tests
// and tools can use it without paying for torch headers.
#include <cstdint>
#include <string>
#include <vector>

#include "affinity/frame.h"
#include "model_config.h"

namespace affinity::train {

// Loads a weights file and runs the torch forward (float32, no autograd) over `frames` as one
// sequence from an empty history: exactly docs/MODEL.md, with none of the inference
// pipeline's own history resets (camera cuts). Returns each frame's output O_t as [H][W][3]
// floats. Throws affinity::Error for bad files or frames of different sizes.
std::vector<std::vector<float>> torchDenoiseSequence(const std::string& weightsPath,
                                                     const std::vector<SampleFrame>& frames);

// Writes a freshly initialised model of `config`; the same (config, seed) gives the same file.
void writeInitialModel(const ModelConfig& config, std::uint64_t seed, const std::string& path);

}  // namespace affinity::train
