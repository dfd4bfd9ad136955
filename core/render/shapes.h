#pragma once
// Shapes as triangle meshes in object space. Every shape fits in [-1, 1]^3:
// sphere of radius 1; box [-1, 1]^3; quad and disk in the XZ plane facing +Y; closed cylinder
// of radius 1 along Y from -1 to 1. Curved surfaces carry smooth vertex normals.
#include <vector>

#include <glm/glm.hpp>

#include "render/scene.h"

namespace affinity::render {

struct Mesh {
    std::vector<glm::vec3> positions;
    std::vector<glm::vec3> normals;  // unit, pointing out of the object
    std::vector<glm::vec2> uvs;
    std::vector<glm::uvec3> triangles;
};

const Mesh& shapeMesh(ShapeType shape);

}  // namespace affinity::render
