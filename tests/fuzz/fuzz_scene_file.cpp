// libFuzzer target: parseScene on arbitrary text. Rejection with affinity::Error is the expected
// outcome; any other exception, a crash, a leak or undefined behaviour is a bug. An accepted scene
// goes on as `affinity render` takes it: written back as scene.json, which must parse again, and
// its camera and objects evaluated at the frames of a sequence.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "affinity/error.h"
#include "render/scene.h"
#include "render/scene_file.h"

namespace {

void touch(const affinity::render::Scene& scene) {
    float sum = 0.0f;
    for (const float frame : {-1.0f, 0.0f, 0.5f, 3.0f, 1e6f}) {
        const affinity::render::CameraKey key = scene.camera.keyAt(frame);
        sum += key.position.x + key.target.y;
        for (const affinity::render::Object& object : scene.objects) sum += object.transformAt(frame).matrix()[3][0];
    }
    volatile float sink = sum;
    (void)sink;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string text(reinterpret_cast<const char*>(data), size);
    affinity::render::Scene scene;
    try {
        scene = affinity::render::parseScene(text, "fuzz input");
    } catch (const affinity::Error&) {
        return 0;
    }
    touch(scene);
    // `affinity render` writes what it rendered as scene.json: that file must read back.
    const std::string written = affinity::render::sceneToJson(scene);
    try {
        touch(affinity::render::parseScene(written, "written back"));
    } catch (const affinity::Error& e) {
        std::fprintf(stderr, "an accepted scene does not read back from its own scene.json: %s\n", e.what());
        std::abort();
    }
    return 0;
}
