#include "render/scene_library.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>

#include "affinity/error.h"
#include "render/procedural.h"
#include "render/scene_file.h"

namespace affinity::render {

namespace fs = std::filesystem;

std::string bundledScenesDirectory() {
    if (const char* dir = std::getenv("AFFINITY_SAMPLES_DIR"); dir && *dir) return (fs::path(dir) / "scenes").string();
    return (fs::path(AFFINITY_DEFAULT_SAMPLES_DIR) / "scenes").string();
}

std::vector<std::string> bundledSceneNames() {
    std::vector<std::string> names;
    std::error_code error;
    for (const auto& entry : fs::directory_iterator(bundledScenesDirectory(), error))
        if (entry.path().extension() == ".json") names.push_back(entry.path().stem().string());
    std::sort(names.begin(), names.end());
    return names;
}

Scene resolveScene(const std::string& nameOrFile) {
    std::string proceduralForms;  // for the error message: "'procedural:SEED' or ..."
    for (ProceduralVariant variant : kProceduralVariants) {
        const std::string prefix = proceduralPrefix(variant);
        proceduralForms += (proceduralForms.empty() ? "'" : " or '") + prefix + "SEED'";
        if (nameOrFile.rfind(prefix, 0) != 0) continue;
        const std::string digits = nameOrFile.substr(prefix.size());
        if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos || digits.size() > 19)
            throw Error("procedural scene '" + nameOrFile + "': the seed must be a non-negative integer");
        return proceduralScene(std::stoull(digits), variant);
    }
    if (fs::is_regular_file(nameOrFile)) return loadSceneFile(nameOrFile);
    const fs::path bundled = fs::path(bundledScenesDirectory()) / (nameOrFile + ".json");
    if (fs::is_regular_file(bundled)) return loadSceneFile(bundled.string());
    std::string known;
    for (const std::string& name : bundledSceneNames()) known += (known.empty() ? "" : ", ") + name;
    throw Error("unknown scene '" + nameOrFile + "': not a file, not " + proceduralForms +
                ", and not a bundled scene (" + (known.empty() ? "none found in " + bundledScenesDirectory() : known) +
                ")");
}

}  // namespace affinity::render
