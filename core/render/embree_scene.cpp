#include "render/embree_scene.h"

#include <pmmintrin.h>
#include <xmmintrin.h>

#include "affinity/error.h"
#include "render/shapes.h"

namespace affinity::render {
namespace {

// One Embree device for the process; Embree devices are thread safe.
RTCDevice device() {
    static RTCDevice instance = [] {
        RTCDevice d = rtcNewDevice(nullptr);
        if (!d)
            throw Error("Embree could not create a device (error " + std::to_string(int(rtcGetDeviceError(nullptr))) +
                        ")");
        return d;
    }();
    return instance;
}

WorldMesh placeMesh(const Mesh& mesh, const glm::mat4& objectToWorld, int material) {
    WorldMesh out;
    out.objectToWorld = objectToWorld;
    out.material = material;
    glm::mat3 normalMatrix = glm::transpose(glm::inverse(glm::mat3(objectToWorld)));
    out.positions.reserve(mesh.positions.size());
    out.normals.reserve(mesh.normals.size());
    for (std::size_t i = 0; i < mesh.positions.size(); ++i) {
        out.positions.push_back(glm::vec3(objectToWorld * glm::vec4(mesh.positions[i], 1.0f)));
        out.normals.push_back(glm::normalize(normalMatrix * mesh.normals[i]));
    }
    out.objectPositions = mesh.positions;
    out.uvs = mesh.uvs;
    out.triangles = mesh.triangles;
    return out;
}

}  // namespace

void enableFastFloatMode() {
    _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
    _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
}

EmbreeScene::EmbreeScene(const Scene& scene, float frame) : scene_(scene) {
    rtcScene_ = rtcNewScene(device());
    meshes_.reserve(scene.objects.size());
    for (std::size_t id = 0; id < scene.objects.size(); ++id) {
        const Object& object = scene.objects[id];
        meshes_.push_back(placeMesh(shapeMesh(object.shape), object.transformAt(frame).matrix(), object.material));
        const WorldMesh& m = meshes_.back();
        RTCGeometry geometry = rtcNewGeometry(device(), RTC_GEOMETRY_TYPE_TRIANGLE);
        // Embree reads the buffers in place; they live as long as this scene.
        rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, m.positions.data(), 0,
                                   sizeof(glm::vec3), m.positions.size());
        rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, m.triangles.data(), 0,
                                   sizeof(glm::uvec3), m.triangles.size());
        rtcCommitGeometry(geometry);
        rtcAttachGeometryByID(rtcScene_, geometry, unsigned(id));
        rtcReleaseGeometry(geometry);
    }
    rtcCommitScene(rtcScene_);
}

EmbreeScene::~EmbreeScene() { rtcReleaseScene(rtcScene_); }

std::optional<SurfaceHit> EmbreeScene::intersect(const glm::vec3& origin, const glm::vec3& direction,
                                                 float maxDistance) const {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRayHit rayHit{};
    rayHit.ray.org_x = origin.x;
    rayHit.ray.org_y = origin.y;
    rayHit.ray.org_z = origin.z;
    rayHit.ray.dir_x = direction.x;
    rayHit.ray.dir_y = direction.y;
    rayHit.ray.dir_z = direction.z;
    rayHit.ray.tnear = 0.0f;
    rayHit.ray.tfar = maxDistance;
    rayHit.ray.mask = 0xffffffffu;
    rayHit.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(rtcScene_, &context, &rayHit);
    if (rayHit.hit.geomID == RTC_INVALID_GEOMETRY_ID) return std::nullopt;

    const WorldMesh& mesh = meshes_[rayHit.hit.geomID];
    const glm::uvec3 tri = mesh.triangles[rayHit.hit.primID];
    const float u = rayHit.hit.u, v = rayHit.hit.v, w = 1.0f - u - v;
    auto blend = [&](const auto& values) { return w * values[tri.x] + u * values[tri.y] + v * values[tri.z]; };

    SurfaceHit hit;
    hit.distance = rayHit.ray.tfar;
    hit.position = origin + direction * hit.distance;
    hit.shadingNormal = glm::normalize(blend(mesh.normals));
    glm::vec3 faceNormal =
        glm::cross(mesh.positions[tri.y] - mesh.positions[tri.x], mesh.positions[tri.z] - mesh.positions[tri.x]);
    hit.geometricNormal = glm::normalize(faceNormal);
    if (glm::dot(hit.geometricNormal, hit.shadingNormal) < 0.0f) hit.geometricNormal = -hit.geometricNormal;
    hit.uv = blend(mesh.uvs);
    hit.objectPosition = blend(mesh.objectPositions);
    hit.object = int(rayHit.hit.geomID);
    hit.material = mesh.material;
    hit.primitive = rayHit.hit.primID;
    return hit;
}

bool EmbreeScene::occluded(const glm::vec3& origin, const glm::vec3& direction, float maxDistance) const {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRay ray{};
    ray.org_x = origin.x;
    ray.org_y = origin.y;
    ray.org_z = origin.z;
    ray.dir_x = direction.x;
    ray.dir_y = direction.y;
    ray.dir_z = direction.z;
    ray.tnear = 0.0f;
    ray.tfar = maxDistance;
    ray.mask = 0xffffffffu;
    rtcOccluded1(rtcScene_, &context, &ray);
    return ray.tfar < 0.0f;  // Embree sets tfar to -inf on a hit
}

}  // namespace affinity::render
