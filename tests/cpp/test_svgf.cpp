// SVGF, the baseline: convergence on a static noisy plane, no ghosting after disocclusions or
// under motion, edges that survive, reset, bad input, odd sizes, thread-count independence.
#include <cmath>
#include <functional>
#include <random>

#include <gtest/gtest.h>
#include <omp.h>

#include "affinity/error.h"
#include "affinity/svgf.h"

using namespace affinity;

namespace {

// What a pixel sees: true radiance = light * albedo; every sample's diffuse radiance is that
// times a random factor uniform in [1 - noise, 1 + noise].
struct Surface {
    float light[3] = {1.0f, 1.0f, 1.0f};
    float albedo[3] = {0.5f, 0.5f, 0.5f};
    float normal[3] = {0.0f, 0.0f, 1.0f};
    float depth = 5.0f;
    float noise = 1.0f;
    float motion[2] = {0.0f, 0.0f};
    bool valid = true;      // history validity (frames after the first)
    float emission = 0.0f;  // > 0: an emitter (or the sky) of this radiance, flagged emissive
};
using Scene = std::function<Surface(int x, int y)>;

SampleFrame makeFrame(int width, int height, int spp, int index, unsigned seed, const Scene& scene) {
    std::mt19937 rng(seed * 7919u + unsigned(index));
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    SampleFrame frame(width, height, spp, true);
    frame.info.frameIndex = index;
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const Surface s = scene(x, y);
            for (int k = 0; k < spp; ++k) {
                float* f = frame.sample(x, y, k);
                const float factor = 1.0f + s.noise * u(rng);
                for (int c = 0; c < 3; ++c) {
                    f[channel::kDiffuse + c] = s.light[c] * s.albedo[c] * factor;
                    f[channel::kSpecular + c] = s.emission;
                    f[channel::kNormal + c] = s.normal[c];
                    f[channel::kAlbedo + c] = s.albedo[c];
                }
                f[channel::kDepth] = s.depth;
                f[channel::kRoughness] = 1.0f;
                f[channel::kEmissive] = s.emission > 0.0f ? 1.0f : 0.0f;
            }
            for (int c = 0; c < 3; ++c) frame.reference(x, y)[c] = s.light[c] * s.albedo[c] + s.emission;
            frame.motion(x, y)[0] = s.motion[0];
            frame.motion(x, y)[1] = s.motion[1];
            frame.valid(x, y) = index > 0 && s.valid ? 1.0f : 0.0f;
        }
    return frame;
}

// Root mean square difference to the frame's reference over the pixels with x in [x0, x1).
double rmse(const std::vector<float>& image, const SampleFrame& frame, int x0 = 0, int x1 = -1) {
    if (x1 < 0) x1 = frame.width();
    double sum = 0.0;
    long long count = 0;
    for (int y = 0; y < frame.height(); ++y)
        for (int x = x0; x < x1; ++x)
            for (int c = 0; c < 3; ++c) {
                const double d = image[(std::size_t(y) * frame.width() + x) * 3 + c] - frame.reference(x, y)[c];
                sum += d * d;
                ++count;
            }
    return std::sqrt(sum / double(count));
}

// Mean of channel c over the pixels with x in [x0, x1).
double columnMean(const std::vector<float>& image, int width, int height, int x0, int x1, int c = 0) {
    double sum = 0.0;
    for (int y = 0; y < height; ++y)
        for (int x = x0; x < x1; ++x) sum += image[(std::size_t(y) * width + x) * 3 + c];
    return sum / double(height * (x1 - x0));
}

bool allFinite(const std::vector<float>& v) {
    for (float x : v)
        if (!std::isfinite(x)) return false;
    return true;
}

Surface plane() {
    Surface s;
    s.light[0] = 1.0f, s.light[1] = 0.8f, s.light[2] = 0.6f;
    return s;
}

}  // namespace

TEST(Svgf, SettingsDefaultsAreThePapers) {
    SvgfSettings s;
    EXPECT_EQ(s.atrousIterations, 5);
    EXPECT_EQ(s.sigmaDepth, 1.0f);
    EXPECT_EQ(s.sigmaNormal, 128.0f);
    EXPECT_EQ(s.sigmaLuminance, 4.0f);
    EXPECT_EQ(s.alphaColor, 0.2f);
    EXPECT_EQ(s.alphaMoments, 0.2f);
    EXPECT_EQ(s.historyCap, 32);
    EXPECT_EQ(s.spatialVarianceFrames, 4);
    EXPECT_EQ(s.feedbackIteration, 0);
}

TEST(Svgf, InvalidSettingsAreRejected) {
    const auto rejects = [](auto change) {
        SvgfSettings s;
        change(s);
        EXPECT_THROW(Svgf{s}, Error);
    };
    rejects([](SvgfSettings& s) { s.atrousIterations = -1; });
    rejects([](SvgfSettings& s) { s.atrousIterations = 11; });
    rejects([](SvgfSettings& s) { s.feedbackIteration = 5; });
    rejects([](SvgfSettings& s) { s.alphaColor = 0.0f; });
    rejects([](SvgfSettings& s) { s.alphaMoments = 1.5f; });
    rejects([](SvgfSettings& s) { s.sigmaLuminance = 0.0f; });
    rejects([](SvgfSettings& s) { s.sigmaDepth = NAN; });
    rejects([](SvgfSettings& s) { s.historyCap = 0; });
    SvgfSettings none;
    none.atrousIterations = 0;
    EXPECT_NO_THROW(Svgf{none});
}

TEST(Svgf, EmptyFrameIsAnError) {
    Svgf svgf;
    EXPECT_THROW(svgf.denoise(SampleFrame{}), Error);
}

// Every stage is a normalised weighted average: noise-free constant input comes back unchanged.
TEST(Svgf, ConstantInputIsReproduced) {
    Svgf svgf;
    Surface s = plane();
    s.noise = 0.0f;
    for (int t = 0; t < 3; ++t) {
        SampleFrame frame = makeFrame(19, 11, 2, t, 1, [&](int, int) { return s; });
        EXPECT_LT(rmse(svgf.denoise(frame), frame), 1e-6) << "frame " << t;
    }
}

TEST(Svgf, StaticNoisyPlaneConvergesFrameOverFrame) {
    Svgf svgf;
    const Scene scene = [](int, int) { return plane(); };
    std::vector<double> error, noisy;
    for (int t = 0; t < 16; ++t) {
        SampleFrame frame = makeFrame(48, 40, 1, t, 2, scene);
        error.push_back(rmse(svgf.denoise(frame), frame));
        noisy.push_back(rmse(frame.meanRadiance(), frame));
    }
    // Noisy input: uniform factor in [0, 2] -> relative std 0.577, RMSE about 0.2.
    EXPECT_GT(noisy[0], 0.15);
    EXPECT_LT(error[0], 0.5 * noisy[0]);
    EXPECT_LT(error[3], 0.8 * error[0]);
    EXPECT_LT(error[15], 0.6 * error[0]);
    EXPECT_LT(error[15], 0.1 * noisy[15]);
    const std::vector<float> lengths = svgf.historyLength();
    ASSERT_EQ(lengths.size(), 48u * 40u);
    for (float h : lengths) ASSERT_EQ(h, 16.0f);
}

TEST(Svgf, HistoryLengthStopsAtTheCap) {
    SvgfSettings settings;
    settings.historyCap = 3;
    Svgf svgf(settings);
    for (int t = 0; t < 6; ++t) svgf.denoise(makeFrame(9, 8, 1, t, 3, [](int, int) { return plane(); }));
    for (float h : svgf.historyLength()) ASSERT_EQ(h, 3.0f);
}

// After 12 frames of a bright surface, the right half changes: by the validity mask, by a depth
// jump, by a normal flip, or by motion from outside the image. The right half must show the
// new, dark value, not a blend with the old one; the left half keeps its history.
TEST(Svgf, DisocclusionDoesNotDragOldColour) {
    const int width = 40, height = 24;
    const std::vector<std::function<void(Surface&)>> changes = {
        [](Surface& s) { s.valid = false; },
        [](Surface& s) { s.depth = 3.0f; },
        [](Surface& s) { s.normal[0] = 1.0f, s.normal[2] = 0.0f; },
        [](Surface& s) { s.motion[0] = 100.0f; },
    };
    for (std::size_t k = 0; k < changes.size(); ++k) {
        Svgf svgf;
        const Scene bright = [](int, int) { return plane(); };
        for (int t = 0; t < 12; ++t) svgf.denoise(makeFrame(width, height, 2, t, 4, bright));
        const Scene changed = [&](int x, int) {
            Surface s = plane();
            if (x >= width / 2) {
                for (float& l : s.light) l *= 0.2f;
                changes[k](s);
            }
            return s;
        };
        const SampleFrame frame = makeFrame(width, height, 2, 12, 4, changed);
        const std::vector<float> out = svgf.denoise(frame);
        // Away from the boundary (the filter's reach there is the edge-stopping's business).
        const double right = columnMean(out, width, height, width / 2 + 4, width);
        EXPECT_NEAR(right, 0.2 * 0.5, 0.015) << "change " << k;
        EXPECT_NEAR(columnMean(out, width, height, 0, width / 2 - 4), 0.5, 0.03) << "change " << k;
        const std::vector<float> lengths = svgf.historyLength();
        EXPECT_EQ(lengths[std::size_t(5) * width + width - 3], 1.0f) << "change " << k;
        EXPECT_EQ(lengths[std::size_t(5) * width + 3], 13.0f) << "change " << k;
    }
}

// A pattern moving one pixel per frame, with correct motion vectors and no noise: the history
// follows it. Without a-trous passes the output is the current frame exactly; with them, the
// first frames' blur (variance estimated spatially across the stripes) fades from the fed-back
// history. Ignoring the motion ghosts.
TEST(Svgf, MovingPatternFollowsTheMotionVectors) {
    const int width = 32, height = 8;
    const auto scene = [](int t, float motion) {
        return [t, motion](int x, int) {
            Surface s = plane();
            s.noise = 0.0f;
            s.light[0] = ((x - t + 64) / 4) % 2 == 0 ? 1.0f : 0.25f;
            s.motion[0] = motion;
            return s;
        };
    };
    SvgfSettings temporalOnly;
    temporalOnly.atrousIterations = 0;
    Svgf exact(temporalOnly), followed, ignored;
    std::vector<double> exactError, followedError, ignoredError;
    for (int t = 0; t < 24; ++t) {
        const SampleFrame a = makeFrame(width, height, 1, t, 5, scene(t, -1.0f));
        const SampleFrame b = makeFrame(width, height, 1, t, 5, scene(t, 0.0f));
        // Column 0 has no history (its motion leaves the image); with the a-trous passes the blur
        // of each newly entered column fades as it moves right, so look at the right half.
        exactError.push_back(rmse(exact.denoise(a), a, 1, width));
        followedError.push_back(rmse(followed.denoise(a), a, 16, width));
        ignoredError.push_back(rmse(ignored.denoise(b), b, 1, width));
    }
    for (double e : exactError) EXPECT_LT(e, 1e-6);
    EXPECT_LT(followedError[23], 0.1 * followedError[3]);  // the blur fades well past this bound
    EXPECT_GT(ignoredError[23], 0.05);
}

// Illumination is the same across each edge and the albedo, normals or depth jump: the output
// must not carry one side's radiance to the other.
TEST(Svgf, EdgesSurviveFiltering) {
    const int width = 40, height = 24;
    const std::vector<std::pair<const char*, std::function<void(Surface&)>>> edges = {
        {"albedo", [](Surface& s) { s.albedo[0] = s.albedo[1] = s.albedo[2] = 0.1f; }},
        {"normal",
         [](Surface& s) { s.normal[0] = 1.0f, s.normal[2] = 0.0f, s.light[0] = s.light[1] = s.light[2] = 0.2f; }},
        {"depth", [](Surface& s) { s.depth = 10.0f, s.light[0] = s.light[1] = s.light[2] = 0.2f; }},
    };
    for (const auto& [name, change] : edges) {
        const Scene scene = [&](int x, int) {
            Surface s;
            s.noise = 0.5f;
            if (x >= width / 2) change(s);
            return s;
        };
        Svgf svgf;
        std::vector<float> out;
        SampleFrame frame;
        for (int t = 0; t < 6; ++t) {
            frame = makeFrame(width, height, 2, t, 6, scene);
            out = svgf.denoise(frame);
        }
        const double left = frame.reference(width / 2 - 1, 0)[0], right = frame.reference(width / 2, 0)[0];
        // The columns either side of the edge.
        EXPECT_NEAR(columnMean(out, width, height, width / 2 - 1, width / 2), left, 0.05 * left) << name;
        EXPECT_NEAR(columnMean(out, width, height, width / 2, width / 2 + 1), right, 0.05 * right) << name;
        EXPECT_NEAR(columnMean(out, width, height, width / 2 + 1, width / 2 + 3), right, 0.05 * right) << name;
    }
}

TEST(Svgf, ResetForgetsHistory) {
    const Scene scene = [](int, int) { return plane(); };
    const SampleFrame f0 = makeFrame(21, 17, 2, 0, 7, scene), f1 = makeFrame(21, 17, 2, 1, 7, scene);
    Svgf a, b;
    a.denoise(f0);
    a.reset();
    EXPECT_TRUE(a.historyLength().empty());
    EXPECT_EQ(a.denoise(f1), b.denoise(f1));
    Svgf c;
    c.denoise(f0);
    EXPECT_NE(c.denoise(f1), b.denoise(f1));  // history does matter
}

TEST(Svgf, BadRadianceAndFeaturesGiveFiniteOutput) {
    Svgf svgf;
    for (int t = 0; t < 3; ++t) {
        SampleFrame frame = makeFrame(16, 12, 2, t, 8, [](int, int) { return plane(); });
        frame.sample(1, 1, 0)[channel::kDiffuse] = NAN;
        frame.sample(2, 1, 1)[channel::kSpecular + 1] = INFINITY;
        frame.sample(3, 1, 0)[channel::kDiffuse + 2] = -5.0f;
        frame.sample(4, 1, 0)[channel::kSpecular] = -INFINITY;
        frame.sample(5, 2, 0)[channel::kAlbedo] = NAN;
        frame.sample(6, 2, 0)[channel::kNormal] = INFINITY;
        frame.sample(7, 2, 0)[channel::kDepth] = NAN;
        frame.sample(8, 2, 1)[channel::kDiffuse] = 3e38f;
        frame.motion(9, 3)[0] = NAN;
        frame.motion(10, 3)[1] = 1e30f;
        const std::vector<float> out = svgf.denoise(frame);
        ASSERT_TRUE(allFinite(out)) << "frame " << t;
        for (float v : out) ASSERT_GE(v, 0.0f);
    }
}

TEST(Svgf, MissesRoundTrip) {
    // The five left columns see the sky: no depth, normal or albedo; emissive radiance.
    Svgf svgf;
    const Scene scene = [](int x, int) {
        Surface s = plane();
        s.noise = 0.0f;
        if (x < 5) {
            s.depth = 0.0f;
            s.normal[2] = 0.0f;
            for (int c = 0; c < 3; ++c) s.albedo[c] = s.light[c] = 0.0f;
            s.emission = 0.7f;
        }
        return s;
    };
    for (int t = 0; t < 3; ++t) {
        const SampleFrame frame = makeFrame(12, 6, 1, t, 9, scene);
        EXPECT_LT(rmse(svgf.denoise(frame), frame), 1e-5) << "frame " << t;
    }
}

// A small bright lamp on a noisy wall (same normal and depth): emission is added back after
// filtering, so the lamp keeps its radiance and none of it spreads to the wall around it.
TEST(Svgf, EmissionIsNeitherFilteredNorSpread) {
    const int width = 24, height = 20;
    const Scene scene = [](int x, int y) {
        Surface s = plane();
        if (x >= 10 && x < 12 && y >= 9 && y < 11) {
            s.emission = 50.0f;
            s.albedo[0] = s.albedo[1] = s.albedo[2] = 0.0f;
        }
        return s;
    };
    Svgf svgf;
    for (int t = 0; t < 4; ++t) {
        const SampleFrame frame = makeFrame(width, height, 2, t, 13, scene);
        const std::vector<float> out = svgf.denoise(frame);
        for (int y = 0; y < height; ++y)
            for (int x = 0; x < width; ++x)
                for (int c = 0; c < 3; ++c) {
                    const float value = out[(std::size_t(y) * width + x) * 3 + c];
                    ASSERT_NEAR(value, frame.reference(x, y)[c], 0.05f) << x << ", " << y << " frame " << t;
                }
    }
}

TEST(Svgf, OddSizesWork) {
    for (const auto& [w, h] : {std::pair{1, 1}, std::pair{7, 13}, std::pair{13, 7}, std::pair{1, 9}, std::pair{9, 1}}) {
        Svgf svgf;
        for (int t = 0; t < 3; ++t) {
            const SampleFrame frame = makeFrame(w, h, 3, t, 10, [](int, int) { return plane(); });
            const std::vector<float> out = svgf.denoise(frame);
            ASSERT_EQ(out.size(), std::size_t(w) * h * 3);
            EXPECT_TRUE(allFinite(out)) << w << "x" << h;
            EXPECT_LT(rmse(out, frame), rmse(frame.meanRadiance(), frame) + 1e-6) << w << "x" << h;
        }
        Surface clean = plane();
        clean.noise = 0.0f;
        const SampleFrame exact = makeFrame(w, h, 1, 3, 10, [&](int, int) { return clean; });
        EXPECT_LT(rmse(Svgf().denoise(exact), exact), 1e-6) << w << "x" << h;
    }
}

TEST(Svgf, ResultsDoNotDependOnTheThreadCount) {
    const int threads = omp_get_max_threads();
    std::vector<std::vector<float>> results[2];
    for (int run = 0; run < 2; ++run) {
        omp_set_num_threads(run == 0 ? 1 : 2);
        Svgf svgf;
        for (int t = 0; t < 4; ++t)
            results[run].push_back(svgf.denoise(makeFrame(37, 29, 2, t, 11, [](int x, int y) {
                Surface s = plane();
                s.depth = 4.0f + 0.05f * float(x) + 0.02f * float(y);
                s.motion[0] = 0.3f;
                s.motion[1] = -0.6f;
                return s;
            })));
    }
    omp_set_num_threads(threads);
    for (int t = 0; t < 4; ++t) EXPECT_EQ(results[0][t], results[1][t]) << "frame " << t;
}

TEST(Svgf, SizeChangeDropsHistory) {
    const Scene scene = [](int, int) { return plane(); };
    Svgf svgf;
    for (int t = 0; t < 4; ++t) svgf.denoise(makeFrame(24, 16, 1, t, 12, scene));
    const SampleFrame smaller = makeFrame(16, 24, 1, 4, 12, scene);
    EXPECT_EQ(svgf.denoise(smaller), Svgf().denoise(smaller));
    for (float h : svgf.historyLength()) ASSERT_EQ(h, 1.0f);
}
