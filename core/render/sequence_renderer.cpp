#include "render/sequence_renderer.h"

#include <atomic>

#include <omp.h>

#include "affinity/error.h"
#include "render/camera_view.h"
#include "render/light_sampler.h"
#include "render/path_tracer.h"
#include "render/rng.h"

namespace affinity::render {
namespace {

Pcg32 sampleRng(std::uint64_t seed, int frameIndex, std::size_t pixel, std::uint64_t sampleIndex) {
    std::uint64_t key = mix64(mix64(mix64(seed) ^ std::uint64_t(frameIndex)) ^ pixel);
    return Pcg32(key, sampleIndex);
}

bool onScreen(const glm::vec2& p, int width, int height) {
    return p.x >= 0.0f && p.y >= 0.0f && p.x < float(width) && p.y < float(height);
}

}  // namespace

SequenceRenderer::SequenceRenderer(const Scene& scene, const RenderSettings& settings)
    : scene_(scene), settings_(settings) {
    if (settings.width < 1 || settings.height < 1 || settings.width > 16384 || settings.height > 16384)
        throw Error("image size " + std::to_string(settings.width) + "x" + std::to_string(settings.height) +
                    " is invalid: each side must be in 1..16384");
    if (settings.spp < 1 || settings.spp > SampleFrame::kMaxSpp)
        throw Error("samples per pixel must be in 1.." + std::to_string(SampleFrame::kMaxSpp) + ", got " +
                    std::to_string(settings.spp));
    if (settings.referenceSpp < 0) throw Error("reference samples per pixel must not be negative");
    scene.validate();
}

SequenceRenderer::~SequenceRenderer() = default;

SampleFrame SequenceRenderer::render(int frameIndex, const ProgressCallback& progress,
                                     const std::function<bool()>& stop) {
    const int width = settings_.width, height = settings_.height;
    auto current = std::make_unique<EmbreeScene>(scene_, float(frameIndex));
    const LightSampler lights(*current);
    const PathTracer tracer(*current, lights, settings_.maxBounces, settings_.featureConvention);
    // The reference is radiance only; the renderer's own convention keeps its sums bit for bit
    // independent of the feature convention (the split's rounding differs between them).
    const PathTracer referenceTracer(*current, lights, settings_.maxBounces);
    const CameraView camera(scene_.camera, float(frameIndex), width, height);

    SampleFrame frame(width, height, settings_.spp, settings_.referenceSpp > 0);
    frame.info.sceneName = scene_.name;
    frame.info.frameIndex = frameIndex;
    frame.info.referenceSpp = settings_.referenceSpp;
    frame.info.seed = settings_.seed;
    frame.info.worldToCamera = camera.worldToCameraRowMajor();
    frame.info.cameraToClip = camera.cameraToClipRowMajor();

    computeMotion(frameIndex, *current, frame);

    std::atomic<int> rowsDone{0};
    std::atomic<bool> stopped{false};
    std::uint64_t rays = 0;
#pragma omp parallel reduction(+ : rays)
    {
        enableFastFloatMode();
        float scratch[kFeatureCount];
#pragma omp for schedule(dynamic, 1)
        for (int y = 0; y < height; ++y) {
            // An exception cannot leave the parallel loop: the remaining rows are skipped.
            if (stop && omp_get_thread_num() == 0 && stop()) stopped = true;
            if (stopped) continue;
            for (int x = 0; x < width; ++x) {
                const std::size_t pixel = frame.pixelIndex(x, y);
                for (int s = 0; s < settings_.spp; ++s) {
                    Pcg32 rng = sampleRng(settings_.seed, frameIndex, pixel, std::uint64_t(s));
                    glm::vec2 jitter(rng.next(), rng.next());
                    rays += std::uint64_t(tracer.trace(camera.position(),
                                                       camera.direction(float(x) + jitter.x, float(y) + jitter.y), rng,
                                                       frame.sample(x, y, s)));
                }
                if (frame.hasReference()) {
                    glm::dvec3 sum(0.0);
                    for (int s = 0; s < settings_.referenceSpp; ++s) {
                        Pcg32 rng = sampleRng(settings_.seed, frameIndex, pixel, kReferenceStream + std::uint64_t(s));
                        glm::vec2 jitter(rng.next(), rng.next());
                        rays += std::uint64_t(referenceTracer.trace(
                            camera.position(), camera.direction(float(x) + jitter.x, float(y) + jitter.y), rng,
                            scratch));
                        for (int c = 0; c < 3; ++c)
                            sum[c] += double(scratch[channel::kDiffuse + c] + scratch[channel::kSpecular + c]);
                    }
                    float* ref = frame.reference(x, y);
                    for (int c = 0; c < 3; ++c) ref[c] = float(sum[c] / double(settings_.referenceSpp));
                }
            }
            int done = ++rowsDone;
            if (progress && omp_get_thread_num() == 0) progress(double(done) / double(height));
        }
    }
    raysCast_ += rays;
    if (stopped) throw Interrupted("render: interrupted in frame " + std::to_string(frameIndex));
    if (progress) progress(1.0);

    previous_ = std::move(current);
    previousIndex_ = frameIndex;
    return frame;
}

// Motion and validity from the ray through each pixel centre: the surface point it hits is
// carried to the previous frame by its object's transform and projected with the previous
// camera; it is valid when on screen and visible there (a ray in the previous frame's scene
// reaches it). Environment pixels reproject by direction alone.
void SequenceRenderer::computeMotion(int frameIndex, const EmbreeScene& current, SampleFrame& frame) const {
    const bool hasHistory = previous_ && previousIndex_ == frameIndex - 1;
    if (!hasHistory) return;  // motion 0, valid 0: the first frame of a sequence has no history
    const int width = frame.width(), height = frame.height();
    const EmbreeScene& previous = *previous_;
    const CameraView camera(scene_.camera, float(frameIndex), width, height);
    const CameraView previousCamera(scene_.camera, float(frameIndex - 1), width, height);

#pragma omp parallel
    {
        enableFastFloatMode();
#pragma omp for schedule(dynamic, 4)
        for (int y = 0; y < height; ++y) {
            for (int x = 0; x < width; ++x) {
                const glm::vec2 centre(float(x) + 0.5f, float(y) + 0.5f);
                const glm::vec3 direction = camera.direction(centre.x, centre.y);
                std::optional<SurfaceHit> hit = current.intersect(camera.position(), direction);
                glm::vec2 previousPixel;
                bool inFront = false, visible = false;
                if (hit) {
                    const glm::mat4& objectToWorld = previous.meshes()[hit->object].objectToWorld;
                    glm::vec3 previousPoint = glm::vec3(objectToWorld * glm::vec4(hit->objectPosition, 1.0f));
                    previousPixel = previousCamera.project(previousPoint, inFront);
                    glm::vec3 toPoint = previousPoint - previousCamera.position();
                    float distance = glm::length(toPoint);
                    std::optional<SurfaceHit> seen = previous.intersect(previousCamera.position(), toPoint / distance);
                    visible = seen && seen->object == hit->object &&
                              std::abs(seen->distance - distance) <= 1e-3f * distance + 1e-4f;
                } else {
                    previousPixel = previousCamera.projectDirection(direction, inFront);
                    visible = !previous.intersect(previousCamera.position(), direction);
                }
                float* motion = frame.motion(x, y);
                if (inFront) {
                    motion[0] = previousPixel.x - centre.x;
                    motion[1] = previousPixel.y - centre.y;
                }
                frame.valid(x, y) = (inFront && visible && onScreen(previousPixel, width, height)) ? 1.0f : 0.0f;
            }
        }
    }
}

}  // namespace affinity::render
