#pragma once
// Seeded procedural scenes for training: random shapes, materials, textures, lights and a
// camera that translates and rotates. Same seed, same scene, on every machine.
#include <cstdint>

#include "render/scene.h"

namespace affinity::render {

// The animation is keyed over frames 0..kProceduralSpan; later frames hold the last pose.
inline constexpr float kProceduralSpan = 16.0f;

// What the generator adds to its base scene. Every variant draws the base scene first with the
// same numbers, so "procedural:SEED" stays the same scene whatever variants exist.
enum class ProceduralVariant {
    Base,
    // 1-4 tiny (sub-pixel to about a pixel wide at training sizes), very bright emitters that
    // drift across the view: sparks, distant lamps and glints, where a pixel's few samples read
    // 0 or thousands and the base scenes' lights are 5-60x dimmer and twice as large.
    Sparks,
};

inline constexpr ProceduralVariant kProceduralVariants[] = {ProceduralVariant::Base, ProceduralVariant::Sparks};

// What a user types before the seed, and the start of the scene's name: "procedural:" or
// "procedural-sparks:".
const char* proceduralPrefix(ProceduralVariant variant);

Scene proceduralScene(std::uint64_t seed, ProceduralVariant variant = ProceduralVariant::Base);

}  // namespace affinity::render
