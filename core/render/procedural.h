#pragma once
// Seeded procedural scenes for training: random shapes, materials, textures, lights and a
// camera that translates and rotates. Same seed, same scene, on every machine.
#include <cstdint>

#include "render/scene.h"

namespace affinity::render {

// The animation is keyed over frames 0..kProceduralSpan; later frames hold the last pose.
inline constexpr float kProceduralSpan = 16.0f;

Scene proceduralScene(std::uint64_t seed);

}  // namespace affinity::render
