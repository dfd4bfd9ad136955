#pragma once
// Writing weights files (docs/MODEL.md section 9). Only training code writes weights files,
// so this lives in its own library, affinity_train_io, which inference never links.
#include <cstdint>
#include <string>
#include <vector>

#include "affinity/weights.h"

namespace affinity::train {

// One tensor to store: `floats` holds the elements of a Float32 tensor, `ints` those of an
// Int32 tensor (row-major, Π shape elements); the other vector stays empty.
struct NamedTensor {
    std::string name;
    DType dtype = DType::Float32;
    std::vector<std::int64_t> shape;
    std::vector<float> floats;
    std::vector<std::int32_t> ints;
};

// The complete file image. Throws affinity::Error naming the tensor for an empty or duplicate
// name, a name with a NUL byte, rank outside 1..4, a dimension < 1, or an element count that
// does not match the shape.
std::vector<std::uint8_t> serializeWeights(const std::vector<NamedTensor>& tensors);

// serializeWeights, written atomically: readers of `path` never see a partial file.
void writeWeightsFile(const std::string& path, const std::vector<NamedTensor>& tensors);

}  // namespace affinity::train
