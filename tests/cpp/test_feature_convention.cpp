// FeatureConvention::Cycles: the features as the Blender extension gets them from Cycles
// (docs/BLENDER.md, "Feature mapping") on the same paths, and the default convention untouched.
#include <cmath>
#include <cstring>

#include <gtest/gtest.h>

#include "affinity/error.h"
#include "render/scene_library.h"
#include "render/sequence_renderer.h"
#include "scene_builders.h"

using namespace affinity;
using namespace affinity::render;

namespace {

SampleFrame renderFrame(const Scene& scene, FeatureConvention convention, int size, int spp, int referenceSpp = 0) {
    RenderSettings settings;
    settings.width = settings.height = size;
    settings.spp = spp;
    settings.referenceSpp = referenceSpp;
    settings.featureConvention = convention;
    SequenceRenderer renderer(scene, settings);
    return renderer.render(0);
}

// Camera at z = 5 looking down -z at a box whose front face (z = 0) fills the middle of the
// image, and a diffuse wall of colour `backdrop` behind the camera at z = 10 (what a mirror
// reflects), another at z = -10.
Scene frontalScene(int& front, glm::vec3 backdrop) {
    Scene scene = test::emptyScene("frontal");
    scene.camera.fovYDegrees = 20.0f;
    scene.environment.top = scene.environment.bottom = glm::vec3(0.3f);
    front = test::addMaterial(scene, MaterialType::Diffuse, glm::vec3(1.0f));
    int back = test::addMaterial(scene, MaterialType::Diffuse, backdrop);
    test::addObject(scene, ShapeType::Box, front, {glm::vec3(0, 0, -0.1f), glm::vec3(0), glm::vec3(5, 5, 0.1f)});
    test::addObject(scene, ShapeType::Quad, back, {glm::vec3(0, 0, 10), glm::vec3(-90, 0, 0), glm::vec3(50)});
    test::addObject(scene, ShapeType::Quad, back, {glm::vec3(0, 0, -10), glm::vec3(90, 0, 0), glm::vec3(50)});
    return scene;
}

Scene frontalScene(MaterialType type, glm::vec3 color, float roughness, glm::vec3 backdrop) {
    int front = 0;
    Scene scene = frontalScene(front, backdrop);
    scene.materials[front].type = type;
    scene.materials[front].roughness = roughness;
    scene.textures[scene.materials[front].texture].colorA = color;
    scene.textures[scene.materials[front].texture].colorB = color;
    return scene;
}

// Calls check(sample) for every sample of the 8x8 pixels in the middle of a 16x16 frame.
template <class Check>
void forCentreSamples(const SampleFrame& frame, Check check) {
    for (int y = 4; y < 12; ++y)
        for (int x = 4; x < 12; ++x)
            for (int s = 0; s < frame.spp(); ++s) check(frame.sample(x, y, s));
}

const glm::vec3 kBackdrop(0.2f, 0.6f, 0.4f);
const glm::vec3 kMetal(0.9f, 0.5f, 0.3f);

}  // namespace

// Roughness 0.1 is GGX alpha 0.01: not a delta lobe for us (v is the metal), but specular for
// Cycles' denoising features, which pass through it to the wall behind the camera, tinted by it.
TEST(FeatureConvention, RoughishMetalIsVForUsAndPassedThroughByCycles) {
    const Scene scene = frontalScene(MaterialType::Conductor, kMetal, 0.1f, kBackdrop);
    const SampleFrame ours = renderFrame(scene, FeatureConvention::Renderer, 16, 2);
    forCentreSamples(ours, [](const float* f) {
        EXPECT_EQ(f[channel::kSpecularBounce], 0.0f);
        EXPECT_EQ(f[channel::kMetallic], 1.0f);
        EXPECT_NEAR(f[channel::kNormal + 2], 1.0f, 1e-5f);
        EXPECT_NEAR(f[channel::kDepth], 5.0f, 0.05f);  // off-axis rays are a little longer
        EXPECT_NEAR(f[channel::kRoughness], 0.1f, 1e-6f);
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(f[channel::kAlbedo + c], kMetal[c], 1e-6f);
    });
    const SampleFrame cycles = renderFrame(scene, FeatureConvention::Cycles, 16, 2);
    forCentreSamples(cycles, [](const float* f) {
        EXPECT_EQ(f[channel::kSpecularBounce], 1.0f);
        EXPECT_EQ(f[channel::kMetallic], 1.0f);            // the first hit's
        EXPECT_NEAR(f[channel::kRoughness], 0.1f, 1e-6f);  // the first hit's
        EXPECT_EQ(f[channel::kEmissive], 0.0f);
        EXPECT_NEAR(f[channel::kNormal + 2], -1.0f, 1e-5f);  // the wall behind the camera
        EXPECT_GT(f[channel::kDepth], 14.9f);                // 5 to the metal + 10 back out,
        EXPECT_LT(f[channel::kDepth], 15.6f);                // a little longer off the mirror direction
        for (int c = 0; c < 3; ++c)                          // Cycles multiplies the chain's tint in
            EXPECT_NEAR(f[channel::kAlbedo + c], kMetal[c] * kBackdrop[c], 1e-6f);
    });
}

// Cycles' threshold, GGX alpha 0.075 (roughness 0.274): as measured in Blender, features are
// written through a metal of roughness 0.27 and on one of roughness 0.28.
TEST(FeatureConvention, CyclesSpecularThresholdIsRoughness0274) {
    const SampleFrame through =
        renderFrame(frontalScene(MaterialType::Conductor, kMetal, 0.27f, kBackdrop), FeatureConvention::Cycles, 16, 1);
    const SampleFrame on =
        renderFrame(frontalScene(MaterialType::Conductor, kMetal, 0.28f, kBackdrop), FeatureConvention::Cycles, 16, 1);
    forCentreSamples(through, [](const float* f) {
        EXPECT_EQ(f[channel::kSpecularBounce], 1.0f);
        EXPECT_GT(f[channel::kDepth], 14.0f);
    });
    forCentreSamples(on, [](const float* f) {
        EXPECT_EQ(f[channel::kSpecularBounce], 0.0f);
        EXPECT_NEAR(f[channel::kDepth], 5.0f, 0.05f);  // off-axis rays are a little longer
        EXPECT_NEAR(f[channel::kNormal + 2], 1.0f, 1e-5f);
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(f[channel::kAlbedo + c], kMetal[c], 1e-6f);
    });
}

// Through a perfect mirror both conventions see the wall, but Cycles' roughness and metallic
// are shader AOVs of the first hit: the mirror's.
TEST(FeatureConvention, MirrorRoughnessAndMetallicComeFromTheFirstHit) {
    const Scene scene = frontalScene(MaterialType::Conductor, kMetal, 0.0f, kBackdrop);
    forCentreSamples(renderFrame(scene, FeatureConvention::Renderer, 16, 2), [](const float* f) {
        EXPECT_EQ(f[channel::kRoughness], 1.0f);  // the diffuse wall
        EXPECT_EQ(f[channel::kMetallic], 0.0f);
        EXPECT_EQ(f[channel::kSpecularBounce], 1.0f);
    });
    forCentreSamples(renderFrame(scene, FeatureConvention::Cycles, 16, 2), [](const float* f) {
        EXPECT_EQ(f[channel::kRoughness], kRoughnessFloor);  // the mirror, clamped to the floor
        EXPECT_EQ(f[channel::kMetallic], 1.0f);
        EXPECT_EQ(f[channel::kSpecularBounce], 1.0f);
        EXPECT_NEAR(f[channel::kDepth], 15.0f, 0.15f);
        EXPECT_NEAR(f[channel::kNormal + 2], -1.0f, 1e-5f);
    });
}

// Clear glass: Cycles' transmissive flag is the first hit's, set on every sample, also on the
// few that take the Fresnel reflection (ours sets it only where the path refracted).
TEST(FeatureConvention, TransmissiveIsTheFirstHitsInCycles) {
    const Scene scene = frontalScene(MaterialType::Dielectric, glm::vec3(1.0f), 0.0f, kBackdrop);
    int oursTransmissive = 0, cyclesTransmissive = 0, total = 0;
    forCentreSamples(renderFrame(scene, FeatureConvention::Renderer, 16, 8),
                     [&](const float* f) { oursTransmissive += f[channel::kTransmissive] == 1.0f; });
    forCentreSamples(renderFrame(scene, FeatureConvention::Cycles, 16, 8), [&](const float* f) {
        cyclesTransmissive += f[channel::kTransmissive] == 1.0f;
        ++total;
        EXPECT_EQ(f[channel::kSpecularBounce], 1.0f);
        EXPECT_EQ(f[channel::kRoughness], kRoughnessFloor);
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(f[channel::kAlbedo + c], kBackdrop[c], 1e-5f);
    });
    EXPECT_EQ(cyclesTransmissive, total);
    EXPECT_LT(oursTransmissive, total);
}

// A pure emitter (black reflectance: Cycles' Emission shader) has no BSDF: Cycles writes normal 0
// and albedo 0 there. Seen directly it is emissive at its depth; seen only through a mirror the
// path reached no BSDF and its first hit does not emit, which the mapping reads as a miss.
TEST(FeatureConvention, PureEmitterHasNoNormalAndThroughAMirrorIsAMiss) {
    Scene direct = frontalScene(MaterialType::Emitter, glm::vec3(0.0f), 1.0f, kBackdrop);
    direct.materials[0].emission = glm::vec3(4.0f);
    forCentreSamples(renderFrame(direct, FeatureConvention::Renderer, 16, 2), [](const float* f) {
        EXPECT_NEAR(f[channel::kNormal + 2], 1.0f, 1e-5f);
        EXPECT_EQ(f[channel::kEmissive], 1.0f);
    });
    forCentreSamples(renderFrame(direct, FeatureConvention::Cycles, 16, 2), [](const float* f) {
        for (int c = 0; c < 3; ++c) {
            EXPECT_EQ(f[channel::kNormal + c], 0.0f);
            EXPECT_EQ(f[channel::kAlbedo + c], 0.0f);
        }
        EXPECT_NEAR(f[channel::kDepth], 5.0f, 0.05f);  // off-axis rays are a little longer
        EXPECT_EQ(f[channel::kEmissive], 1.0f);
        EXPECT_EQ(f[channel::kRoughness], 1.0f);
        EXPECT_EQ(f[channel::kSpecularBounce], 0.0f);
    });

    int wall = 0;
    Scene mirrored = frontalScene(wall, kBackdrop);
    mirrored.materials[wall].type = MaterialType::Conductor;
    mirrored.materials[wall].roughness = 0.0f;
    mirrored.materials[1].type = MaterialType::Emitter;  // the walls
    mirrored.textures[mirrored.materials[1].texture].colorA = glm::vec3(0.0f);
    mirrored.textures[mirrored.materials[1].texture].colorB = glm::vec3(0.0f);
    mirrored.materials[1].emission = glm::vec3(2.0f);
    forCentreSamples(renderFrame(mirrored, FeatureConvention::Renderer, 16, 2), [](const float* f) {
        EXPECT_NEAR(f[channel::kDepth], 15.0f, 0.15f);
        EXPECT_EQ(f[channel::kEmissive], 1.0f);
    });
    forCentreSamples(renderFrame(mirrored, FeatureConvention::Cycles, 16, 2), [](const float* f) {
        EXPECT_EQ(f[channel::kDepth], 0.0f);
        EXPECT_EQ(f[channel::kRoughness], 0.0f);
        EXPECT_EQ(f[channel::kEmissive], 1.0f);
        EXPECT_EQ(f[channel::kMetallic], 0.0f);
        EXPECT_EQ(f[channel::kSpecularBounce], 1.0f);
        for (int c = 0; c < 3; ++c) EXPECT_EQ(f[channel::kNormal + c], 0.0f);
    });
}

// Cycles' light passes split by the first hit's closure: everything seen through a mirror is
// glossy (specular); ours splits at the diffuse wall. The total is the same path's.
TEST(FeatureConvention, RadianceSplitsAtTheFirstHitInCycles) {
    const Scene scene = frontalScene(MaterialType::Conductor, kMetal, 0.0f, kBackdrop);
    const SampleFrame ours = renderFrame(scene, FeatureConvention::Renderer, 16, 4);
    const SampleFrame cycles = renderFrame(scene, FeatureConvention::Cycles, 16, 4);
    double oursDiffuse = 0.0, cyclesDiffuse = 0.0, oursTotal = 0.0, cyclesTotal = 0.0;
    forCentreSamples(ours, [&](const float* f) {
        for (int c = 0; c < 3; ++c) {
            oursDiffuse += f[channel::kDiffuse + c];
            oursTotal += f[channel::kDiffuse + c] + f[channel::kSpecular + c];
        }
    });
    forCentreSamples(cycles, [&](const float* f) {
        for (int c = 0; c < 3; ++c) {
            cyclesDiffuse += f[channel::kDiffuse + c];
            cyclesTotal += f[channel::kDiffuse + c] + f[channel::kSpecular + c];
        }
    });
    EXPECT_GT(oursDiffuse, 0.5 * oursTotal);
    EXPECT_EQ(cyclesDiffuse, 0.0);
    EXPECT_GT(cyclesTotal, 0.0);
    EXPECT_NEAR(cyclesTotal, oursTotal, 1e-5 * oursTotal);
}

// On every bundled scene: the default is the renderer convention bit for bit, and the Cycles
// convention traces the same paths (same total radiance per sample, same reference) and stays
// within the features' ranges.
TEST(FeatureConvention, DefaultIsUnchangedAndCyclesTracesTheSamePaths) {
    for (const std::string& name : bundledSceneNames()) {
        const Scene scene = resolveScene(name);
        RenderSettings defaults;
        defaults.width = 32;
        defaults.height = 24;
        defaults.spp = 2;
        defaults.referenceSpp = 4;
        RenderSettings explicitRenderer = defaults, cyclesSettings = defaults;
        explicitRenderer.featureConvention = FeatureConvention::Renderer;
        cyclesSettings.featureConvention = FeatureConvention::Cycles;
        const SampleFrame a = SequenceRenderer(scene, defaults).render(0);
        const SampleFrame b = SequenceRenderer(scene, explicitRenderer).render(0);
        const SampleFrame c = SequenceRenderer(scene, cyclesSettings).render(0);
        ASSERT_EQ(a.samples().size(), b.samples().size());
        EXPECT_EQ(std::memcmp(a.samples().data(), b.samples().data(), a.samples().size() * sizeof(float)), 0) << name;
        EXPECT_EQ(std::memcmp(a.reference().data(), c.reference().data(), a.reference().size() * sizeof(float)), 0)
            << name;
        int differing = 0;
        for (std::size_t i = 0; i < a.pixelCount() * std::size_t(a.spp()); ++i) {
            const float* fa = a.samples().data() + i * kFeatureCount;
            const float* fc = c.samples().data() + i * kFeatureCount;
            for (int k = 0; k < 3; ++k) {
                const float totalA = fa[channel::kDiffuse + k] + fa[channel::kSpecular + k];
                const float totalC = fc[channel::kDiffuse + k] + fc[channel::kSpecular + k];
                ASSERT_NEAR(totalC, totalA, 1e-4f * (1.0f + totalA)) << name;
            }
            for (const FeatureGroup& group : kFeatureGroups)
                for (int k = group.offset; k < group.offset + group.count; ++k) {
                    ASSERT_GE(fc[k], group.minValue) << name << " " << featureChannelName(k);
                    ASSERT_LE(fc[k], group.maxValue) << name << " " << featureChannelName(k);
                }
            differing += std::memcmp(fa, fc, kFeatureCount * sizeof(float)) != 0;
        }
        // Where only diffuse surfaces are in view (e.g. disocclusion's lamp is out of this
        // frame) both conventions agree; glossy, refraction and fireflies show metal, glass or lamps.
        if (name == "glossy" || name == "refraction" || name == "fireflies") {
            EXPECT_GT(differing, 0) << name;
        }
    }
}

TEST(FeatureConvention, NamesRoundTripAndUnknownNamesAreErrors) {
    EXPECT_EQ(parseFeatureConvention("renderer"), FeatureConvention::Renderer);
    EXPECT_EQ(parseFeatureConvention("cycles"), FeatureConvention::Cycles);
    EXPECT_STREQ(featureConventionName(FeatureConvention::Cycles), "cycles");
    EXPECT_STREQ(featureConventionName(FeatureConvention::Renderer), "renderer");
    EXPECT_THROW(parseFeatureConvention("blender"), Error);
}
