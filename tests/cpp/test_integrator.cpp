// The path tracer against closed-form answers: furnaces, constant environments, convergence
// rate, determinism.
#include <cmath>

#include <gtest/gtest.h>
#include <omp.h>

#include "render/sequence_renderer.h"
#include "scene_builders.h"

using namespace affinity;
using namespace affinity::render;

namespace {

// Mean radiance over all samples of all pixels, per channel.
glm::dvec3 meanRadiance(const SampleFrame& frame) {
    glm::dvec3 sum(0.0);
    std::vector<float> mean = frame.meanRadiance();
    for (std::size_t i = 0; i < frame.pixelCount(); ++i)
        for (int c = 0; c < 3; ++c) sum[c] += mean[3 * i + c];
    return sum / double(frame.pixelCount());
}

SampleFrame renderOne(const Scene& scene, int size, int spp, std::uint64_t seed = 1, int referenceSpp = 0) {
    RenderSettings settings;
    settings.width = settings.height = size;
    settings.spp = spp;
    settings.referenceSpp = referenceSpp;
    settings.seed = seed;
    SequenceRenderer renderer(scene, settings);
    return renderer.render(0);
}

}  // namespace

// Inside a closed box whose walls have albedo a and emit E, every point sees L = E / (1 - a).
TEST(Integrator, ClosedFurnaceGivesEmissionOverOneMinusAlbedo) {
    for (float albedo : {0.3f, 0.7f}) {
        Scene scene = test::emptyScene("furnace");
        int wall = test::addMaterial(scene, MaterialType::Emitter, glm::vec3(albedo), 0.5f, 1.5f, glm::vec3(1.0f));
        // Six quads facing inwards (a quad faces +Y before rotation).
        const std::pair<glm::vec3, glm::vec3> faces[] = {{{0, -10, 0}, {0, 0, 0}},   {{0, 10, 0}, {180, 0, 0}},
                                                         {{0, 0, -10}, {90, 0, 0}},  {{0, 0, 10}, {-90, 0, 0}},
                                                         {{-10, 0, 0}, {0, 0, -90}}, {{10, 0, 0}, {0, 0, 90}}};
        for (const auto& [position, rotation] : faces)
            test::addObject(scene, ShapeType::Quad, wall, {position, rotation, glm::vec3(10.0f)});
        glm::dvec3 mean = meanRadiance(renderOne(scene, 16, 64));
        const double expected = 1.0 / (1.0 - albedo);
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(mean[c], expected, 0.01 * expected) << "albedo " << albedo;
    }
}

// A convex object in a constant environment sees only the environment: one bounce, L = a * Le
// for a Lambertian sphere, L = Le for a perfect mirror with F0 = 1 and for lossless glass.
TEST(Integrator, ConstantEnvironmentAroundConvexObjects) {
    struct Case {
        MaterialType type;
        float roughness;
        glm::vec3 color;
        double expected;
    };
    const Case cases[] = {{MaterialType::Diffuse, 1.0f, glm::vec3(0.6f), 0.6},
                          {MaterialType::Conductor, 0.0f, glm::vec3(1.0f), 1.0},
                          {MaterialType::Dielectric, 0.0f, glm::vec3(1.0f), 1.0}};
    for (const Case& c : cases) {
        Scene scene = test::emptyScene("environment");
        scene.environment.top = scene.environment.bottom = glm::vec3(1.0f);
        int material = test::addMaterial(scene, c.type, c.color, c.roughness);
        // Camera at z = 5 looking at a sphere that fills the whole view.
        scene.camera.fovYDegrees = 10.0f;
        test::addObject(scene, ShapeType::Sphere, material, {glm::vec3(0.0f), glm::vec3(0.0f), glm::vec3(1.5f)});
        glm::dvec3 mean = meanRadiance(renderOne(scene, 16, 64));
        for (int k = 0; k < 3; ++k) EXPECT_NEAR(mean[k], c.expected, 0.01 * c.expected) << "material " << int(c.type);
    }
}

// Independent samples: the error of an n-sample mean against the converged image falls as
// 1/sqrt(n), so 16 samples have half the RMS error of 4.
TEST(Integrator, ErrorShrinksAsOneOverSquareRootOfSamples) {
    Scene scene = test::emptyScene("convergence");
    scene.environment.top = glm::vec3(1.0f);
    scene.environment.bottom = glm::vec3(0.1f);
    int diffuse = test::addMaterial(scene, MaterialType::Diffuse, glm::vec3(0.7f, 0.5f, 0.3f));
    int glossy = test::addMaterial(scene, MaterialType::Conductor, glm::vec3(0.9f), 0.3f);
    test::addObject(scene, ShapeType::Quad, diffuse, {glm::vec3(0, -1, 0), glm::vec3(0), glm::vec3(10)});
    test::addObject(scene, ShapeType::Sphere, glossy, {glm::vec3(0), glm::vec3(0), glm::vec3(1)});
    SampleFrame frame = renderOne(scene, 24, 16, 7, 4096);

    auto rmse = [&](int n) {
        double sum = 0.0;
        for (int y = 0; y < frame.height(); ++y)
            for (int x = 0; x < frame.width(); ++x)
                for (int c = 0; c < 3; ++c) {
                    double mean = 0.0;
                    for (int s = 0; s < n; ++s)
                        mean += frame.sample(x, y, s)[channel::kDiffuse + c] +
                                frame.sample(x, y, s)[channel::kSpecular + c];
                    double d = mean / n - frame.reference(x, y)[c];
                    sum += d * d;
                }
        return std::sqrt(sum / double(frame.pixelCount() * 3));
    };
    double ratio = rmse(4) / rmse(16);
    EXPECT_GT(ratio, 1.7);
    EXPECT_LT(ratio, 2.3);
}

TEST(Integrator, SameSeedSameImageWhateverTheThreadCount) {
    Scene scene = test::emptyScene("determinism");
    scene.environment.top = glm::vec3(1.0f);
    int material = test::addMaterial(scene, MaterialType::Plastic, glm::vec3(0.5f, 0.2f, 0.1f), 0.2f);
    test::addObject(scene, ShapeType::Sphere, material, {glm::vec3(0), glm::vec3(0), glm::vec3(1)});
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    SampleFrame one = renderOne(scene, 12, 2, 3, 8);
    omp_set_num_threads(std::max(2, threads));
    SampleFrame many = renderOne(scene, 12, 2, 3, 8);
    omp_set_num_threads(threads);
    EXPECT_EQ(one.samples(), many.samples());
    EXPECT_EQ(one.reference(), many.reference());
    SampleFrame otherSeed = renderOne(scene, 12, 2, 4, 8);
    EXPECT_NE(one.samples(), otherSeed.samples());
}
