// The scene description format and the scene library: bundled scenes load, errors name the
// key, procedural scenes are reproducible.
#include <algorithm>
#include <set>

#include <gtest/gtest.h>

#include "affinity/error.h"
#include "render/procedural.h"
#include "render/scene_file.h"
#include "render/scene_library.h"

using namespace affinity;
using namespace affinity::render;

namespace {

std::string errorOf(const std::string& json) {
    try {
        parseScene(json, "test.json");
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

const char* kMinimal = R"({
  "camera": {"position": [0, 1, 5], "target": [0, 0, 0]},
  "materials": {"grey": {"type": "diffuse", "color": 0.5}},
  "objects": [{"shape": "sphere", "material": "grey"}]
})";

}  // namespace

TEST(SceneFile, BundledScenesLoad) {
    const std::vector<std::string> names = bundledSceneNames();
    for (const char* expected : {"disocclusion", "glossy", "refraction", "thin_geometry", "fireflies", "fine_texture",
                                 "low_light"})
        EXPECT_NE(std::find(names.begin(), names.end(), expected), names.end()) << expected;
    for (const std::string& name : names) {
        Scene scene = resolveScene(name);
        EXPECT_EQ(scene.name, name);
        EXPECT_FALSE(scene.objects.empty());
    }
}

TEST(SceneFile, MinimalSceneParses) {
    Scene scene = parseScene(kMinimal, "minimal");
    ASSERT_EQ(scene.objects.size(), 1u);
    EXPECT_EQ(scene.materials[0].type, MaterialType::Diffuse);
    EXPECT_EQ(scene.textures[scene.materials[0].texture].colorA, glm::vec3(0.5f));
}

TEST(SceneFile, ErrorsNameTheFileAndTheKey) {
    std::string json = kMinimal;
    auto replaced = [&](const std::string& from, const std::string& to) {
        std::string s = json;
        s.replace(s.find(from), from.size(), to);
        return s;
    };
    EXPECT_NE(errorOf(replaced("\"grey\"}", "\"gray\"}")).find("objects[0].material: unknown material 'gray'"),
              std::string::npos);
    EXPECT_NE(errorOf(replaced("\"shape\"", "\"shap\"")).find("objects[0]: unknown key \"shap\""), std::string::npos);
    EXPECT_NE(errorOf(replaced("\"sphere\"", "\"teapot\"")).find("unknown value 'teapot'"), std::string::npos);
    EXPECT_NE(errorOf(replaced("\"diffuse\", \"color\": 0.5", "\"diffuse\", \"color\": [1, 2]"))
                  .find("materials.grey.color"),
              std::string::npos);
    EXPECT_NE(errorOf("{ not json").find("test.json"), std::string::npos);
}

TEST(SceneFile, UnknownSceneListsTheKnownOnes) {
    try {
        resolveScene("no_such_scene");
        FAIL() << "expected an error";
    } catch (const Error& e) {
        std::string message = e.what();
        EXPECT_NE(message.find("unknown scene 'no_such_scene'"), std::string::npos);
        EXPECT_NE(message.find("disocclusion"), std::string::npos);
    }
    EXPECT_THROW(resolveScene("procedural:12x"), Error);
}

TEST(SceneFile, ProceduralScenesAreReproducibleAndVaried) {
    EXPECT_EQ(sceneToJson(proceduralScene(5)), sceneToJson(proceduralScene(5)));
    EXPECT_NE(sceneToJson(proceduralScene(5)), sceneToJson(proceduralScene(6)));
    // Over many seeds the generator uses every material type and moves the camera.
    std::set<MaterialType> types;
    for (std::uint64_t seed = 0; seed < 50; ++seed) {
        Scene scene = proceduralScene(seed);
        for (const Material& m : scene.materials) types.insert(m.type);
        ASSERT_EQ(scene.camera.keys.size(), 2u);
        EXPECT_NE(scene.camera.keys[0].position, scene.camera.keys[1].position);
    }
    EXPECT_EQ(types.size(), 5u);
}

TEST(SceneFile, TheSparksVariantAddsMovingTinyBrightLampsToTheSameBaseScene) {
    for (std::uint64_t seed : {3u, 4u, 5u}) {
        const Scene base = proceduralScene(seed);
        const Scene sparks = resolveScene("procedural-sparks:" + std::to_string(seed));
        // The base scene comes first, object for object (its draws are unchanged).
        ASSERT_GT(sparks.objects.size(), base.objects.size());
        ASSERT_LE(sparks.objects.size(), base.objects.size() + 4);
        for (std::size_t i = 0; i < base.objects.size(); ++i)
            EXPECT_EQ(sparks.objects[i].transformAt(2.0f).matrix(), base.objects[i].transformAt(2.0f).matrix());
        EXPECT_EQ(sparks.camera.keys[1].position, base.camera.keys[1].position);
        for (std::size_t i = base.objects.size(); i < sparks.objects.size(); ++i) {
            const Object& spark = sparks.objects[i];
            const Material& m = sparks.materials[spark.material];
            EXPECT_EQ(m.type, MaterialType::Emitter);
            // As bright as the base scenes' brightest small lamp (400) or up to 15x brighter, and
            // at most 0.04 in radius (theirs: 0.05).
            const float brightest = std::max({m.emission.x, m.emission.y, m.emission.z});
            EXPECT_GE(brightest, 399.0f);
            EXPECT_LE(brightest, 6001.0f);
            EXPECT_LE(spark.transformAt(0.0f).scale.x, 0.04f);
            EXPECT_NE(spark.transformAt(0.0f).translate, spark.transformAt(kProceduralSpan).translate);
        }
    }
    EXPECT_THROW(resolveScene("procedural-sparks:"), Error);
}

TEST(SceneFile, WrittenScenesReadBackToTheSameScene) {
    Scene original = proceduralScene(11);
    Scene copy = parseScene(sceneToJson(original), "copy");
    ASSERT_EQ(copy.objects.size(), original.objects.size());
    for (std::size_t i = 0; i < original.objects.size(); ++i) {
        EXPECT_EQ(copy.objects[i].keys.size(), original.objects[i].keys.size());
        EXPECT_EQ(copy.objects[i].transformAt(3.0f).matrix(), original.objects[i].transformAt(3.0f).matrix());
        const Material& a = original.materials[original.objects[i].material];
        const Material& b = copy.materials[copy.objects[i].material];
        EXPECT_EQ(a.type, b.type);
        EXPECT_EQ(a.roughness, b.roughness);
        EXPECT_EQ(original.textures[a.texture].colorA, copy.textures[b.texture].colorA);
    }
}
