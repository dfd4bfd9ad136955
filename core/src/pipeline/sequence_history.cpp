#include "pipeline/sequence_history.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "pipeline/exposure.h"

namespace affinity {
namespace {

// Angle in degrees between two cameras' viewing directions, and the distance between them.
void cameraChange(const Matrix4& a, const Matrix4& b, double& degrees, double& distance) {
    // Row 2 of world-to-camera is the camera's +Z axis in world space; the position is
    // -R^T t.
    double dot = 0.0;
    for (int i = 0; i < 3; ++i) dot += double(a[8 + i]) * b[8 + i];
    degrees = std::acos(std::clamp(dot, -1.0, 1.0)) * 180.0 / 3.14159265358979;
    distance = 0.0;
    for (int i = 0; i < 3; ++i) {
        double pa = 0.0, pb = 0.0;
        for (int r = 0; r < 3; ++r) {
            pa -= double(a[r * 4 + i]) * a[r * 4 + 3];
            pb -= double(b[r * 4 + i]) * b[r * 4 + 3];
        }
        distance += (pa - pb) * (pa - pb);
    }
    distance = std::sqrt(distance);
}

}  // namespace

bool SequenceHistory::applies(int width, int height, const FrameInfo& info, float meanDepth,
                              std::string& reason) const {
    double degrees = 0.0, distance = 0.0;
    cameraChange(lastWorldToCamera_, info.worldToCamera, degrees, distance);
    if (width != lastWidth_ || height != lastHeight_)
        reason = "frame size changed";
    else if (degrees > 45.0)
        reason = "camera turned by " + std::to_string(int(degrees)) + " degrees";
    else if (meanDepth > 0.0f && distance > 0.5 * std::max(meanDepth, lastMeanDepth_))
        reason = "camera moved by more than half the scene depth";
    else
        return true;
    return false;
}

bool SequenceHistory::continuedBy(int width, int height, const FrameInfo& info, float meanDepth) const {
    std::string ignored;
    return has_ && applies(width, height, info, meanDepth, ignored);
}

bool SequenceHistory::continuedByCamera(int width, int height, const FrameInfo& info) const {
    return continuedBy(width, height, info, lastMeanDepth_);
}

bool SequenceHistory::continuedBySize(int width, int height) const {
    return has_ && width == lastWidth_ && height == lastHeight_;
}

bool SequenceHistory::startFrame(int width, int height, const FrameInfo& info, float meanDepth, bool useHistory,
                                 std::string& resetReason) {
    if (has_ && !applies(width, height, info, meanDepth, resetReason)) has_ = false;
    lastWidth_ = width;
    lastHeight_ = height;
    lastWorldToCamera_ = info.worldToCamera;
    lastMeanDepth_ = meanDepth;
    if (!useHistory) has_ = false;
    return has_;
}

void SequenceHistory::keep(FeatureMap&& accumulatedEmbedding, FeatureMap&& accumulatedSignal) {
    embedding = std::move(accumulatedEmbedding);
    signal = std::move(accumulatedSignal);
    has_ = true;
}

float SequenceHistory::exposureFor(const SampleBands& samples, int height, bool startsSequence) {
    if (startsSequence || exposure_ <= 0.0f) exposure_ = exposureOf(samples, height);
    return exposure_ > 0.0f ? exposure_ : 1.0f;
}

}  // namespace affinity
