#pragma once
// Finds a scene by what a user typed: a scene file path, "procedural:SEED" (or
// "procedural-sparks:SEED", procedural.h), or the name of a
// bundled test scene in samples/scenes/.
#include <string>
#include <vector>

#include "render/scene.h"

namespace affinity::render {

// The folder of bundled scenes: $AFFINITY_SAMPLES_DIR/scenes if set, else the source tree's.
std::string bundledScenesDirectory();
// Names of the bundled scenes, sorted.
std::vector<std::string> bundledSceneNames();
// Throws affinity::Error listing the known names when nothing matches.
Scene resolveScene(const std::string& nameOrFile);

}  // namespace affinity::render
