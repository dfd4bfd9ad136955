#pragma once
// The pinhole camera at one frame: ray generation and the inverse, projection of world points
// to pixels. Ray generation and projection use the same matrices, so reprojection is exact.
#include <glm/glm.hpp>

#include "affinity/frame.h"
#include "render/scene.h"

namespace affinity::render {

class CameraView {
public:
    CameraView(const Camera& camera, float frame, int width, int height);

    glm::vec3 position() const { return position_; }
    // Unit world direction through image point (px, py) in pixels, y down.
    glm::vec3 direction(float px, float py) const;
    // Pixel position of a world point; `inFront` is false when it is behind the camera.
    glm::vec2 project(const glm::vec3& worldPoint, bool& inFront) const;
    // Pixel position of a direction at infinity (the environment).
    glm::vec2 projectDirection(const glm::vec3& worldDirection, bool& inFront) const;

    Matrix4 worldToCameraRowMajor() const;
    Matrix4 cameraToClipRowMajor() const;

private:
    glm::vec2 projectCameraSpace(const glm::vec3& cameraSpace, bool& inFront) const;

    glm::vec3 position_;
    glm::mat4 worldToCamera_, cameraToWorld_, projection_;
    float tanHalfFov_, aspect_;
    int width_, height_;
};

}  // namespace affinity::render
