// Motion vectors and history validity against geometry computed independently in the test.
#include <cmath>

#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>

#include "render/scene_library.h"
#include "render/sequence_renderer.h"
#include "scene_builders.h"

using namespace affinity;
using namespace affinity::render;

namespace {

// Pixel position of a world point for a camera key, from glm's own projection routine.
glm::dvec2 expectedPixel(const CameraKey& key, const Camera& camera, glm::vec3 point, int width, int height) {
    glm::dmat4 view = glm::lookAt(glm::dvec3(key.position), glm::dvec3(key.target), glm::dvec3(camera.up));
    glm::dmat4 projection =
        glm::perspective(glm::radians(double(camera.fovYDegrees)), double(width) / height, 0.01, 1000.0);
    glm::dvec3 window = glm::project(glm::dvec3(point), view, projection, glm::dvec4(0, 0, width, height));
    return {window.x, double(height) - window.y};  // glm's window y points up
}

// Where the ray through pixel centre (px, py) meets the plane z = planeZ.
glm::dvec3 hitOnPlane(const CameraKey& key, const Camera& camera, double px, double py, int width, int height,
                      double planeZ) {
    glm::dmat4 view = glm::lookAt(glm::dvec3(key.position), glm::dvec3(key.target), glm::dvec3(camera.up));
    glm::dmat4 projection =
        glm::perspective(glm::radians(double(camera.fovYDegrees)), double(width) / height, 0.01, 1000.0);
    glm::dvec4 viewport(0, 0, width, height);
    glm::dvec3 nearPoint = glm::unProject(glm::dvec3(px, height - py, 0.0), view, projection, viewport);
    glm::dvec3 farPoint = glm::unProject(glm::dvec3(px, height - py, 1.0), view, projection, viewport);
    double t = (planeZ - nearPoint.z) / (farPoint.z - nearPoint.z);
    return nearPoint + t * (farPoint - nearPoint);
}

}  // namespace

// A wall translating sideways seen by a camera that moves and turns: every pixel's motion
// must land on where the same wall point was in the previous frame.
TEST(Motion, ReprojectsKnownPointsToWithinAHundredthOfAPixel) {
    Scene scene = test::emptyScene("moving wall");
    scene.environment.top = scene.environment.bottom = glm::vec3(0.5f);
    int material = test::addMaterial(scene, MaterialType::Diffuse, glm::vec3(0.5f));
    Object wall{"wall", ShapeType::Quad, material, {}};
    const glm::vec3 shift(0.3f, 0.1f, 0.0f);
    wall.keys.push_back({0.0f, {glm::vec3(0, 0, -2), glm::vec3(90, 0, 0), glm::vec3(50)}});
    wall.keys.push_back({1.0f, {glm::vec3(0, 0, -2) + shift, glm::vec3(90, 0, 0), glm::vec3(50)}});
    scene.objects.push_back(wall);
    scene.camera.keys = {{0.0f, {0.0f, 0.0f, 5.0f}, {0.0f, 0.0f, 0.0f}},
                         {1.0f, {0.4f, 0.2f, 4.5f}, {0.3f, -0.1f, 0.0f}}};

    RenderSettings settings;
    settings.width = 40;
    settings.height = 30;
    settings.spp = 1;
    settings.referenceSpp = 0;
    SequenceRenderer renderer(scene, settings);
    SampleFrame first = renderer.render(0);
    SampleFrame second = renderer.render(1);

    for (float v : first.valid()) EXPECT_EQ(v, 0.0f);  // no history for the first frame
    double worst = 0.0;
    for (int y = 0; y < settings.height; ++y) {
        for (int x = 0; x < settings.width; ++x) {
            glm::dvec3 now =
                hitOnPlane(scene.camera.keys[1], scene.camera, x + 0.5, y + 0.5, settings.width, settings.height, -2.0);
            glm::dvec2 before = expectedPixel(scene.camera.keys[0], scene.camera, glm::vec3(now) - shift,
                                              settings.width, settings.height);
            const float* motion = second.motion(x, y);
            worst =
                std::max({worst, std::abs(x + 0.5 + motion[0] - before.x), std::abs(y + 0.5 + motion[1] - before.y)});
            bool onScreen = before.x >= 0 && before.y >= 0 && before.x < settings.width && before.y < settings.height;
            EXPECT_EQ(second.valid(x, y), onScreen ? 1.0f : 0.0f) << x << "," << y;
        }
    }
    EXPECT_LT(worst, 0.01);
}

// Background pixels move with the camera's rotation only.
TEST(Motion, EnvironmentFollowsCameraRotation) {
    Scene scene = test::emptyScene("sky");
    scene.environment.top = glm::vec3(1.0f);
    scene.camera.keys = {{0.0f, {0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, -1.0f}},
                         {1.0f, {2.0f, 0.0f, 0.0f}, {2.1f, 0.0f, -1.0f}}};
    RenderSettings settings;
    settings.width = 32;
    settings.height = 32;
    settings.spp = 1;
    settings.referenceSpp = 0;
    SequenceRenderer renderer(scene, settings);
    renderer.render(0);
    SampleFrame frame = renderer.render(1);
    double worst = 0.0;
    for (int y = 0; y < settings.height; ++y) {
        for (int x = 0; x < settings.width; ++x) {
            // A far point in the pixel's direction stands for the direction at infinity.
            glm::dvec3 far =
                hitOnPlane(scene.camera.keys[1], scene.camera, x + 0.5, y + 0.5, settings.width, settings.height, -1e4);
            glm::dvec3 direction = glm::normalize(far - glm::dvec3(scene.camera.keys[1].position));
            glm::dvec2 before = expectedPixel(scene.camera.keys[0], scene.camera,
                                              glm::vec3(glm::dvec3(scene.camera.keys[0].position) + 1e4 * direction),
                                              settings.width, settings.height);
            const float* motion = frame.motion(x, y);
            worst =
                std::max({worst, std::abs(x + 0.5 + motion[0] - before.x), std::abs(y + 0.5 + motion[1] - before.y)});
        }
    }
    EXPECT_LT(worst, 0.01);
}

// In the bundled disocclusion scene a pillar slides across a static view: pixels the pillar
// covered in the previous frame and uncovers now have no history; static background pixels
// away from it keep theirs.
TEST(Motion, DisoccludedPixelsAreInvalid) {
    Scene scene = resolveScene("disocclusion");
    RenderSettings settings;
    settings.width = 64;
    settings.height = 48;
    settings.spp = 4;
    settings.referenceSpp = 0;
    SequenceRenderer renderer(scene, settings);
    // The pillar's albedo marks it in the features: (0.1, 0.35, 0.15).
    auto pillarCoverage = [&](const SampleFrame& frame, int x, int y) {
        int count = 0;
        for (int s = 0; s < frame.spp(); ++s) {
            const float* f = frame.sample(x, y, s);
            count += std::abs(f[channel::kAlbedo] - 0.1f) < 1e-3f && std::abs(f[channel::kAlbedo + 1] - 0.35f) < 1e-3f;
        }
        return count;
    };
    SampleFrame previous = renderer.render(3);
    SampleFrame current = renderer.render(4);
    int disoccluded = 0, disoccludedInvalid = 0, background = 0, backgroundValid = 0;
    for (int y = 0; y < settings.height; ++y) {
        for (int x = 0; x < settings.width; ++x) {
            // Deep inside the pillar's previous footprint: the pixel and its neighbours were covered
            // by every sample, so the pixel centre surely was.
            bool wasPillar = true;
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    int qx = std::clamp(x + dx, 0, settings.width - 1), qy = std::clamp(y + dy, 0, settings.height - 1);
                    wasPillar = wasPillar && pillarCoverage(previous, qx, qy) == settings.spp;
                }
            bool isPillar = pillarCoverage(current, x, y) > 0;
            if (wasPillar && !isPillar) {
                ++disoccluded;
                disoccludedInvalid += current.valid(x, y) == 0.0f;
            }
            bool nearPillar = false;
            for (int dy = -2; dy <= 2; ++dy)
                for (int dx = -2; dx <= 2; ++dx) {
                    int qx = std::clamp(x + dx, 0, settings.width - 1), qy = std::clamp(y + dy, 0, settings.height - 1);
                    nearPillar =
                        nearPillar || pillarCoverage(previous, qx, qy) > 0 || pillarCoverage(current, qx, qy) > 0;
                }
            if (!nearPillar) {
                ++background;
                backgroundValid += current.valid(x, y) == 1.0f;
            }
        }
    }
    ASSERT_GT(disoccluded, 20);
    EXPECT_EQ(disoccludedInvalid, disoccluded);
    ASSERT_GT(background, settings.width * settings.height / 2);
    EXPECT_EQ(backgroundValid, background);
}
