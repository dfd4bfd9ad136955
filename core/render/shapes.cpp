#include "render/shapes.h"

#include <glm/gtc/constants.hpp>

namespace affinity::render {
namespace {

constexpr float kPi = glm::pi<float>();

// Adds a (rows+1) x (cols+1) vertex grid and its triangles; `at(u, v)` gives position and normal.
template <typename Surface>
void addGrid(Mesh& mesh, int cols, int rows, Surface at) {
    auto base = unsigned(mesh.positions.size());
    for (int r = 0; r <= rows; ++r) {
        for (int c = 0; c <= cols; ++c) {
            glm::vec2 uv(float(c) / float(cols), float(r) / float(rows));
            auto [p, n] = at(uv);
            mesh.positions.push_back(p);
            mesh.normals.push_back(n);
            mesh.uvs.push_back(uv);
        }
    }
    auto index = [&](int c, int r) { return base + unsigned(r * (cols + 1) + c); };
    for (int r = 0; r < rows; ++r) {
        for (int c = 0; c < cols; ++c) {
            mesh.triangles.push_back({index(c, r), index(c + 1, r), index(c + 1, r + 1)});
            mesh.triangles.push_back({index(c, r), index(c + 1, r + 1), index(c, r + 1)});
        }
    }
}

using PointNormal = std::pair<glm::vec3, glm::vec3>;

Mesh makeSphere() {
    Mesh m;
    addGrid(m, 96, 48, [](glm::vec2 uv) {
        float phi = 2.0f * kPi * uv.x, theta = kPi * uv.y;
        glm::vec3 p(std::sin(theta) * std::cos(phi), std::cos(theta), -std::sin(theta) * std::sin(phi));
        return PointNormal{p, p};
    });
    return m;
}

// A planar square [-1, 1]^2 spanned by axes a and b with normal n = a x b, offset along n.
void addFace(Mesh& m, glm::vec3 a, glm::vec3 b, float offset) {
    glm::vec3 n = glm::cross(a, b);
    addGrid(m, 1, 1, [&](glm::vec2 uv) {
        return PointNormal{n * offset + a * (2.0f * uv.x - 1.0f) + b * (2.0f * uv.y - 1.0f), n};
    });
}

Mesh makeBox() {
    Mesh m;
    const glm::vec3 x(1, 0, 0), y(0, 1, 0), z(0, 0, 1);
    addFace(m, y, z, 1.0f);  // +X
    addFace(m, z, y, 1.0f);  // -X (z x y = -x)
    addFace(m, z, x, 1.0f);  // +Y
    addFace(m, x, z, 1.0f);  // -Y
    addFace(m, x, y, 1.0f);  // +Z
    addFace(m, y, x, 1.0f);  // -Z
    return m;
}

Mesh makeQuad() {
    Mesh m;
    addFace(m, glm::vec3(0, 0, 1), glm::vec3(1, 0, 0), 0.0f);  // z x x = +y
    return m;
}

// A disk of radius 1 at height y, facing +Y or -Y.
void addDisk(Mesh& m, float y, bool up) {
    glm::vec3 n(0, up ? 1.0f : -1.0f, 0);
    addGrid(m, 64, 1, [&](glm::vec2 uv) {
        float phi = 2.0f * kPi * (up ? uv.x : 1.0f - uv.x);
        return PointNormal{glm::vec3(uv.y * std::cos(phi), y, -uv.y * std::sin(phi)), n};
    });
}

Mesh makeDisk() {
    Mesh m;
    addDisk(m, 0.0f, true);
    return m;
}

Mesh makeCylinder() {
    Mesh m;
    addGrid(m, 64, 1, [](glm::vec2 uv) {
        float phi = 2.0f * kPi * uv.x;
        glm::vec3 n(std::cos(phi), 0.0f, -std::sin(phi));
        return PointNormal{n + glm::vec3(0, 2.0f * uv.y - 1.0f, 0), n};
    });
    addDisk(m, 1.0f, true);
    addDisk(m, -1.0f, false);
    return m;
}

}  // namespace

const Mesh& shapeMesh(ShapeType shape) {
    static const Mesh sphere = makeSphere(), box = makeBox(), quad = makeQuad(), cylinder = makeCylinder(),
                      disk = makeDisk();
    switch (shape) {
    case ShapeType::Sphere:
        return sphere;
    case ShapeType::Box:
        return box;
    case ShapeType::Quad:
        return quad;
    case ShapeType::Cylinder:
        return cylinder;
    case ShapeType::Disk:
        return disk;
    }
    return sphere;
}

}  // namespace affinity::render
