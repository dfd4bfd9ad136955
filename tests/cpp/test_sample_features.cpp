// The 18 per-sample features: ranges on every bundled scene, and the meaning of the
// first-non-specular-vertex rule through mirrors and glass.
#include <cmath>

#include <gtest/gtest.h>

#include "render/scene_library.h"
#include "render/sequence_renderer.h"
#include "scene_builders.h"

using namespace affinity;
using namespace affinity::render;

namespace {

SampleFrame renderFrame(const Scene& scene, int width, int height, int spp) {
    RenderSettings settings;
    settings.width = width;
    settings.height = height;
    settings.spp = spp;
    settings.referenceSpp = 0;
    SequenceRenderer renderer(scene, settings);
    return renderer.render(0);
}

// Camera at z = 5 looking at a large quad at z = 0 (facing the camera) with the given material,
// and a diffuse backdrop of colour `backdrop` behind the camera (what a mirror reflects).
Scene frontalScene(MaterialType type, float roughness, glm::vec3 backdrop) {
    Scene scene = test::emptyScene("frontal");
    scene.camera.fovYDegrees = 20.0f;
    scene.environment.top = scene.environment.bottom = glm::vec3(0.3f);
    int front = test::addMaterial(scene, type, glm::vec3(1.0f), roughness);
    int back = test::addMaterial(scene, MaterialType::Diffuse, backdrop);
    test::addObject(scene, ShapeType::Box, front, {glm::vec3(0, 0, -0.1f), glm::vec3(0), glm::vec3(5, 5, 0.1f)});
    test::addObject(scene, ShapeType::Quad, back, {glm::vec3(0, 0, 10), glm::vec3(-90, 0, 0), glm::vec3(50)});
    test::addObject(scene, ShapeType::Quad, back, {glm::vec3(0, 0, -10), glm::vec3(90, 0, 0), glm::vec3(50)});
    return scene;
}

}  // namespace

TEST(SampleFeatures, EveryBundledSceneStaysInItsRanges) {
    const std::vector<std::string> names = bundledSceneNames();
    ASSERT_GE(names.size(), 7u);
    for (const std::string& name : names) {
        SampleFrame frame = renderFrame(resolveScene(name), 32, 24, 2);
        for (std::size_t i = 0; i < frame.pixelCount() * std::size_t(frame.spp()); ++i) {
            const float* f = frame.samples().data() + i * kFeatureCount;
            for (const FeatureGroup& group : kFeatureGroups)
                for (int c = group.offset; c < group.offset + group.count; ++c) {
                    ASSERT_TRUE(std::isfinite(f[c])) << name << " " << featureChannelName(c);
                    ASSERT_GE(f[c], group.minValue) << name << " " << featureChannelName(c);
                    ASSERT_LE(f[c], group.maxValue) << name << " " << featureChannelName(c);
                }
            for (int c = channel::kEmissive; c < kFeatureCount; ++c)
                ASSERT_TRUE(f[c] == 0.0f || f[c] == 1.0f) << name << " " << featureChannelName(c);
            double normalLength = std::sqrt(f[channel::kNormal] * f[channel::kNormal] +
                                            f[channel::kNormal + 1] * f[channel::kNormal + 1] +
                                            f[channel::kNormal + 2] * f[channel::kNormal + 2]);
            bool hit = f[channel::kDepth] > 0.0f;
            ASSERT_NEAR(normalLength, hit ? 1.0 : 0.0, 1e-4) << name;
            ASSERT_GE(f[channel::kRoughness], hit ? kRoughnessFloor : 0.0f) << name;
        }
    }
}

// Through a perfect mirror the features describe the reflected surface, flagged as seen via a
// specular bounce; the depth is the whole path length.
TEST(SampleFeatures, MirrorShowsTheReflectedSurface) {
    const glm::vec3 backdrop(0.2f, 0.6f, 0.4f);
    SampleFrame frame = renderFrame(frontalScene(MaterialType::Conductor, 0.0f, backdrop), 16, 16, 2);
    for (int y = 4; y < 12; ++y)
        for (int x = 4; x < 12; ++x)
            for (int s = 0; s < 2; ++s) {
                const float* f = frame.sample(x, y, s);
                EXPECT_EQ(f[channel::kSpecularBounce], 1.0f);
                EXPECT_EQ(f[channel::kMetallic], 0.0f);  // the backdrop is not metal
                for (int c = 0; c < 3; ++c) EXPECT_NEAR(f[channel::kAlbedo + c], backdrop[c], 1e-5f);
                EXPECT_NEAR(f[channel::kNormal + 2], -1.0f, 1e-3f);  // backdrop behind the camera faces -z
                EXPECT_NEAR(f[channel::kDepth], 15.0f, 0.3f);        // 5 to the mirror + 10 back out
            }
    // A rough conductor is itself the first non-specular vertex.
    SampleFrame rough = renderFrame(frontalScene(MaterialType::Conductor, 0.4f, backdrop), 16, 16, 1);
    const float* f = rough.sample(8, 8, 0);
    EXPECT_EQ(f[channel::kSpecularBounce], 0.0f);
    EXPECT_EQ(f[channel::kMetallic], 1.0f);
    EXPECT_NEAR(f[channel::kRoughness], 0.4f, 1e-6f);
    EXPECT_NEAR(f[channel::kDepth], 5.0f, 0.01f);
}

// Through clear glass the features describe the surface behind it and the transmissive flag
// is set; the few samples that take the Fresnel reflection instead see the other backdrop.
TEST(SampleFeatures, GlassShowsTheAlbedoOfTheSurfaceBehindIt) {
    const glm::vec3 backdrop(0.2f, 0.6f, 0.4f);
    SampleFrame frame = renderFrame(frontalScene(MaterialType::Dielectric, 0.0f, backdrop), 16, 16, 8);
    int transmitted = 0, total = 0;
    for (int y = 4; y < 12; ++y)
        for (int x = 4; x < 12; ++x)
            for (int s = 0; s < 8; ++s, ++total) {
                const float* f = frame.sample(x, y, s);
                EXPECT_EQ(f[channel::kSpecularBounce], 1.0f);
                for (int c = 0; c < 3; ++c) EXPECT_NEAR(f[channel::kAlbedo + c], backdrop[c], 1e-5f);
                transmitted += f[channel::kTransmissive] == 1.0f;
            }
    // Fresnel reflection at normal incidence on n = 1.5 is 4% per surface.
    EXPECT_GT(transmitted, total * 80 / 100);
    EXPECT_LT(transmitted, total);
}

TEST(SampleFeatures, RadianceSplitsIntoDiffuseAndSpecularByMaterial) {
    Scene scene = frontalScene(MaterialType::Diffuse, 1.0f, glm::vec3(0.5f));
    SampleFrame diffuse = renderFrame(scene, 8, 8, 4);
    double diffuseSum = 0.0, specularSum = 0.0;
    for (std::size_t i = 0; i < diffuse.pixelCount() * 4; ++i) {
        diffuseSum += diffuse.samples()[i * kFeatureCount + channel::kDiffuse];
        specularSum += diffuse.samples()[i * kFeatureCount + channel::kSpecular];
    }
    EXPECT_GT(diffuseSum, 0.0);
    EXPECT_EQ(specularSum, 0.0);
    SampleFrame metal = renderFrame(frontalScene(MaterialType::Conductor, 0.4f, glm::vec3(0.5f)), 8, 8, 4);
    diffuseSum = specularSum = 0.0;
    for (std::size_t i = 0; i < metal.pixelCount() * 4; ++i) {
        diffuseSum += metal.samples()[i * kFeatureCount + channel::kDiffuse];
        specularSum += metal.samples()[i * kFeatureCount + channel::kSpecular];
    }
    EXPECT_EQ(diffuseSum, 0.0);
    EXPECT_GT(specularSum, 0.0);
}
