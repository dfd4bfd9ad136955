#pragma once
// Data augmentation that keeps the physics of a training clip (docs/TRAINING.md): transforms of
// the image plane with the motion vectors transformed alike, and colour channel permutations.
#include <array>
#include <cstdint>
#include <random>

#include <ATen/core/Tensor.h>

namespace affinity::train {

// A crop of a sequence: samples [T, S, 18, h, w], motion [T, 2, h, w] (dx, dy), valid
// [T, 1, h, w], reference [T, 3, h, w].
struct Clip {
    at::Tensor samples, motion, valid, reference;
};

// Transpose first (x <-> y, so dx <-> dy), then flips (x -> w-1-x negates dx, y -> h-1-y negates
// dy): the 8 rotations and reflections of a square. colours[c] is the source channel of output
// colour c, applied to diffuse, specular, albedo and the reference together. Normals are
// world-space and stay as they are.
struct Augmentation {
    bool transpose = false, flipX = false, flipY = false;
    std::array<std::int64_t, 3> colours{0, 1, 2};
};

Augmentation randomAugmentation(std::mt19937_64& rng);
// Requires square crops when `transpose` is set and the shapes above.
void applyAugmentation(Clip& clip, const Augmentation& augmentation);

}  // namespace affinity::train
