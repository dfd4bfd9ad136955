#pragma once
// The scene description file format (JSON), documented in docs/SCENE_FORMAT.md.
#include <string>

#include "render/scene.h"

namespace affinity::render {

// Throws affinity::Error naming the file and the offending key.
Scene loadSceneFile(const std::string& path);
Scene parseScene(const std::string& json, const std::string& sourceName);
// The same format back: parseScene(sceneToJson(s)) reproduces s.
std::string sceneToJson(const Scene& scene);

}  // namespace affinity::render
