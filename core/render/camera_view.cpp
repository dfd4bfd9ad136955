#include "render/camera_view.h"

#include <glm/gtc/matrix_transform.hpp>

#include "affinity/error.h"

namespace affinity::render {
namespace {

Matrix4 toRowMajor(const glm::mat4& m) {
    Matrix4 out{};
    for (int row = 0; row < 4; ++row)
        for (int col = 0; col < 4; ++col) out[row * 4 + col] = m[col][row];  // glm is column-major
    return out;
}

}  // namespace

CameraView::CameraView(const Camera& camera, float frame, int width, int height) : width_(width), height_(height) {
    CameraKey key = camera.keyAt(frame);
    if (glm::length(key.target - key.position) <= 0.0f)
        throw Error("camera position and target coincide at frame " + std::to_string(frame));
    position_ = key.position;
    worldToCamera_ = glm::lookAt(key.position, key.target, camera.up);
    cameraToWorld_ = glm::inverse(worldToCamera_);
    aspect_ = float(width) / float(height);
    tanHalfFov_ = std::tan(glm::radians(camera.fovYDegrees) * 0.5f);
    projection_ = glm::perspective(glm::radians(camera.fovYDegrees), aspect_, 0.01f, 1000.0f);
}

glm::vec3 CameraView::direction(float px, float py) const {
    float ndcX = 2.0f * px / float(width_) - 1.0f;
    float ndcY = 1.0f - 2.0f * py / float(height_);
    glm::vec3 d(ndcX * tanHalfFov_ * aspect_, ndcY * tanHalfFov_, -1.0f);
    return glm::normalize(glm::vec3(cameraToWorld_ * glm::vec4(d, 0.0f)));
}

glm::vec2 CameraView::project(const glm::vec3& worldPoint, bool& inFront) const {
    return projectCameraSpace(glm::vec3(worldToCamera_ * glm::vec4(worldPoint, 1.0f)), inFront);
}

glm::vec2 CameraView::projectDirection(const glm::vec3& worldDirection, bool& inFront) const {
    return projectCameraSpace(glm::vec3(worldToCamera_ * glm::vec4(worldDirection, 0.0f)), inFront);
}

glm::vec2 CameraView::projectCameraSpace(const glm::vec3& c, bool& inFront) const {
    inFront = c.z < 0.0f;
    float depth = inFront ? -c.z : 1.0f;
    float ndcX = c.x / (depth * tanHalfFov_ * aspect_);
    float ndcY = c.y / (depth * tanHalfFov_);
    return {(ndcX + 1.0f) * 0.5f * float(width_), (1.0f - ndcY) * 0.5f * float(height_)};
}

Matrix4 CameraView::worldToCameraRowMajor() const { return toRowMajor(worldToCamera_); }
Matrix4 CameraView::cameraToClipRowMajor() const { return toRowMajor(projection_); }

}  // namespace affinity::render
