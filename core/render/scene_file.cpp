#include "render/scene_file.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>

#include <nlohmann/json.hpp>

#include "affinity/error.h"

namespace affinity::render {
namespace {

using Json = nlohmann::json;

// Parsing context: the source name and the JSON path, for error messages.
class Reader {
public:
    explicit Reader(std::string source) : source_(std::move(source)) {}

    [[noreturn]] void fail(const std::string& where, const std::string& what) const {
        throw Error("scene " + source_ + ": " + where + ": " + what);
    }

    // Read as double and range-checked before narrowing: a float cannot hold 1e60, and an
    // infinite coordinate or roughness would only surface as NaN radiance.
    float number(const Json& j, const std::string& where) const {
        if (!j.is_number()) fail(where, "expected a number");
        const double value = j.get<double>();
        if (!(std::abs(value) <= double(std::numeric_limits<float>::max())))
            fail(where, "expected a finite number, got " + j.dump());
        return float(value);
    }
    float numberIn(const Json& j, float lo, float hi, const std::string& where) const {
        const float value = number(j, where);
        if (value < lo || value > hi)
            fail(where, "must be in [" + format(lo) + ", " + format(hi) + "], got " + format(value));
        return value;
    }
    glm::vec3 vec3(const Json& j, const std::string& where) const {
        if (j.is_number()) return glm::vec3(number(j, where));
        if (!j.is_array() || j.size() != 3) fail(where, "expected [x, y, z] or a number");
        return {number(j[0], where), number(j[1], where), number(j[2], where)};
    }
    // Reflectance, F0, transmission tint: fractions of the light, so a surface neither creates
    // energy (above 1) nor turns radiance negative.
    glm::vec3 color(const Json& j, const std::string& where) const {
        const glm::vec3 c = vec3(j, where);
        if (glm::any(glm::lessThan(c, glm::vec3(0.0f))) || glm::any(glm::greaterThan(c, glm::vec3(1.0f))))
            fail(where, "a colour must be in [0, 1], got " + format(c));
        return c;
    }
    // Emission and the environment: radiance, any brightness but never negative.
    glm::vec3 radiance(const Json& j, const std::string& where) const {
        const glm::vec3 c = vec3(j, where);
        if (glm::any(glm::lessThan(c, glm::vec3(0.0f)))) fail(where, "radiance must not be negative, got " + format(c));
        return c;
    }
    std::string string(const Json& j, const std::string& where) const {
        if (!j.is_string()) fail(where, "expected a string");
        return j.get<std::string>();
    }
    const Json& member(const Json& object, const char* key, const std::string& where) const {
        auto it = object.find(key);
        if (it == object.end()) fail(where, std::string("missing \"") + key + "\"");
        return *it;
    }
    template <typename Enum>
    Enum choice(const Json& j, const std::map<std::string, Enum>& options, const std::string& where) const {
        std::string name = string(j, where);
        auto it = options.find(name);
        if (it != options.end()) return it->second;
        std::string known;
        for (const auto& [key, value] : options) known += (known.empty() ? "" : ", ") + key;
        fail(where, "unknown value '" + name + "' (expected one of: " + known + ")");
    }
    // Rejects keys the format does not know: a misspelt key must not be silently ignored.
    void onlyKeys(const Json& object, std::initializer_list<const char*> keys, const std::string& where) const {
        if (!object.is_object()) fail(where, "expected an object");
        for (const auto& [key, value] : object.items()) {
            bool known = false;
            for (const char* k : keys) known = known || key == k;
            if (!known) fail(where, "unknown key \"" + key + "\"");
        }
    }

    static std::string format(float value) {
        char text[32];
        std::snprintf(text, sizeof text, "%g", double(value));
        return text;
    }
    static std::string format(const glm::vec3& v) {
        return "[" + format(v.x) + ", " + format(v.y) + ", " + format(v.z) + "]";
    }

private:
    std::string source_;
};

const std::map<std::string, TextureType> kTextureTypes{
    {"constant", TextureType::Constant}, {"checker", TextureType::Checker}, {"noise", TextureType::Noise}};
const std::map<std::string, MaterialType> kMaterialTypes{{"diffuse", MaterialType::Diffuse},
                                                         {"conductor", MaterialType::Conductor},
                                                         {"dielectric", MaterialType::Dielectric},
                                                         {"plastic", MaterialType::Plastic},
                                                         {"emitter", MaterialType::Emitter}};
const std::map<std::string, ShapeType> kShapes{{"sphere", ShapeType::Sphere},
                                               {"box", ShapeType::Box},
                                               {"quad", ShapeType::Quad},
                                               {"cylinder", ShapeType::Cylinder},
                                               {"disk", ShapeType::Disk}};

template <typename Enum>
std::string nameOf(const std::map<std::string, Enum>& options, Enum value) {
    for (const auto& [key, v] : options)
        if (v == value) return key;
    return "";
}

Transform readTransform(const Reader& r, const Json& j, const std::string& where) {
    Transform t;
    if (j.contains("translate")) t.translate = r.vec3(j["translate"], where + ".translate");
    if (j.contains("rotate")) t.rotateDegrees = r.vec3(j["rotate"], where + ".rotate");
    if (j.contains("scale")) t.scale = r.vec3(j["scale"], where + ".scale");
    return t;
}

Json vec(const glm::vec3& v) { return Json::array({v.x, v.y, v.z}); }

// Keyframes must be in increasing frame order; `where(k)` is the key path of key k.
template <typename Key, typename Where>
void checkKeyOrder(const Reader& r, const std::vector<Key>& keys, const Where& where) {
    for (std::size_t k = 1; k < keys.size(); ++k)
        if (keys[k].frame <= keys[k - 1].frame)
            r.fail(where(k) + ".frame", "keyframes must be in increasing frame order, got " +
                                            Reader::format(keys[k].frame) + " after " +
                                            Reader::format(keys[k - 1].frame));
}

// The camera must look somewhere at every frame: position and target apart, and `up` not along
// the view direction (glm::lookAt would give NaN). Between two keys both move linearly, so the
// view vector target - position is d0 + w (d1 - d0): it passes through zero only when d0 and
// d1 point in opposite directions, at w = |d0| / (|d0| + |d1|).
void checkCamera(const Reader& r, const Camera& camera, bool keyed) {
    const auto where = [&](std::size_t k) {
        return keyed ? "camera.keys[" + std::to_string(k) + "]" : std::string("camera");
    };
    if (glm::length(camera.up) <= 0.0f) r.fail("camera.up", "must not be zero");
    const glm::vec3 up = glm::normalize(camera.up);
    for (std::size_t k = 0; k < camera.keys.size(); ++k) {
        const glm::vec3 view = camera.keys[k].target - camera.keys[k].position;
        if (glm::length(view) <= 0.0f) r.fail(where(k), "position and target coincide");
        if (glm::length(glm::cross(glm::normalize(view), up)) < 1e-6f)
            r.fail("camera.up", "parallel to the view direction at " + where(k));
        if (k == 0) continue;
        const glm::vec3 previous = camera.keys[k - 1].target - camera.keys[k - 1].position;
        const float a = glm::length(previous), b = glm::length(view);
        if (glm::dot(previous, view) < 0.0f && glm::length(glm::cross(previous, view)) <= 1e-6f * a * b) {
            const float frame = glm::mix(camera.keys[k - 1].frame, camera.keys[k].frame, a / (a + b));
            r.fail(where(k - 1) + " to " + where(k), "position and target coincide at frame " + Reader::format(frame) +
                                                         ", where the camera passes through its target");
        }
    }
}

}  // namespace

Scene parseScene(const std::string& text, const std::string& sourceName) {
    Reader r(sourceName);
    Json root;
    try {
        root = Json::parse(text);
    } catch (const Json::exception& e) {  // parse_error, and out_of_range for numbers beyond a double
        r.fail("JSON", e.what());
    }
    r.onlyKeys(root, {"name", "camera", "environment", "textures", "materials", "objects"}, "top level");
    Scene scene;
    scene.name = root.contains("name") ? r.string(root["name"], "name") : sourceName;

    std::map<std::string, int> textureIds, materialIds;
    scene.textures.push_back(Texture{});  // index 0: default constant grey
    if (root.contains("textures")) {
        const Json& textures = root["textures"];
        if (!textures.is_object()) r.fail("textures", "expected an object of named textures");
        for (const auto& [name, j] : textures.items()) {
            std::string where = "textures." + name;
            r.onlyKeys(j, {"type", "a", "b", "color", "scale"}, where);
            Texture t;
            t.type = r.choice(r.member(j, "type", where), kTextureTypes, where + ".type");
            if (j.contains("color")) t.colorA = t.colorB = r.color(j["color"], where + ".color");
            if (j.contains("a")) t.colorA = r.color(j["a"], where + ".a");
            if (j.contains("b")) t.colorB = r.color(j["b"], where + ".b");
            if (j.contains("scale")) t.scale = r.number(j["scale"], where + ".scale");
            textureIds[name] = int(scene.textures.size());
            scene.textures.push_back(t);
        }
    }

    const Json& materials = r.member(root, "materials", "top level");
    if (!materials.is_object()) r.fail("materials", "expected an object of named materials");
    for (const auto& [name, j] : materials.items()) {
        std::string where = "materials." + name;
        r.onlyKeys(j, {"type", "color", "texture", "roughness", "ior", "emission"}, where);
        Material m;
        m.type = r.choice(r.member(j, "type", where), kMaterialTypes, where + ".type");
        if (j.contains("texture") && j.contains("color")) r.fail(where, "give either \"color\" or \"texture\"");
        if (j.contains("texture")) {
            std::string texture = r.string(j["texture"], where + ".texture");
            if (!textureIds.count(texture)) r.fail(where + ".texture", "unknown texture '" + texture + "'");
            m.texture = textureIds[texture];
        } else if (j.contains("color")) {
            Texture constant;
            constant.colorA = constant.colorB = r.color(j["color"], where + ".color");
            m.texture = int(scene.textures.size());
            scene.textures.push_back(constant);
        }
        if (j.contains("roughness")) m.roughness = r.numberIn(j["roughness"], 0.0f, 1.0f, where + ".roughness");
        if (j.contains("ior")) m.ior = r.numberIn(j["ior"], 1.0f, 4.0f, where + ".ior");
        if (j.contains("emission")) m.emission = r.radiance(j["emission"], where + ".emission");
        materialIds[name] = int(scene.materials.size());
        scene.materials.push_back(m);
    }

    const Json& objects = r.member(root, "objects", "top level");
    if (!objects.is_array()) r.fail("objects", "expected an array");
    for (std::size_t i = 0; i < objects.size(); ++i) {
        const Json& j = objects[i];
        std::string where = "objects[" + std::to_string(i) + "]";
        r.onlyKeys(j, {"name", "shape", "material", "translate", "rotate", "scale", "keys"}, where);
        Object o;
        o.name = j.contains("name") ? r.string(j["name"], where + ".name") : where;
        o.shape = r.choice(r.member(j, "shape", where), kShapes, where + ".shape");
        std::string material = r.string(r.member(j, "material", where), where + ".material");
        if (!materialIds.count(material)) r.fail(where + ".material", "unknown material '" + material + "'");
        o.material = materialIds[material];
        if (j.contains("keys")) {
            if (!j["keys"].is_array() || j["keys"].empty()) r.fail(where + ".keys", "expected a non-empty array");
            for (std::size_t k = 0; k < j["keys"].size(); ++k) {
                const Json& key = j["keys"][k];
                std::string keyWhere = where + ".keys[" + std::to_string(k) + "]";
                r.onlyKeys(key, {"frame", "translate", "rotate", "scale"}, keyWhere);
                // A key starts from the object's static transform and overrides what it names.
                TransformKey tk{r.number(r.member(key, "frame", keyWhere), keyWhere + ".frame"),
                                readTransform(r, j, where)};
                Transform overrides = readTransform(r, key, keyWhere);
                if (key.contains("translate")) tk.transform.translate = overrides.translate;
                if (key.contains("rotate")) tk.transform.rotateDegrees = overrides.rotateDegrees;
                if (key.contains("scale")) tk.transform.scale = overrides.scale;
                o.keys.push_back(tk);
            }
            checkKeyOrder(r, o.keys, [&](std::size_t k) { return where + ".keys[" + std::to_string(k) + "]"; });
        } else {
            o.keys.push_back({0.0f, readTransform(r, j, where)});
        }
        scene.objects.push_back(o);
    }

    if (root.contains("environment")) {
        const Json& j = root["environment"];
        r.onlyKeys(j, {"color", "top", "bottom"}, "environment");
        if (j.contains("color"))
            scene.environment.top = scene.environment.bottom = r.radiance(j["color"], "environment.color");
        if (j.contains("top")) scene.environment.top = r.radiance(j["top"], "environment.top");
        if (j.contains("bottom")) scene.environment.bottom = r.radiance(j["bottom"], "environment.bottom");
    }

    const Json& camera = r.member(root, "camera", "top level");
    r.onlyKeys(camera, {"fov", "up", "position", "target", "keys"}, "camera");
    if (camera.contains("fov")) {
        scene.camera.fovYDegrees = r.number(camera["fov"], "camera.fov");
        if (!(scene.camera.fovYDegrees > 0.0f && scene.camera.fovYDegrees < 180.0f))
            r.fail("camera.fov", "must be in (0, 180) degrees, got " + Reader::format(scene.camera.fovYDegrees));
    }
    if (camera.contains("up")) scene.camera.up = r.vec3(camera["up"], "camera.up");
    if (camera.contains("keys")) {
        if (!camera["keys"].is_array() || camera["keys"].empty()) r.fail("camera.keys", "expected a non-empty array");
        for (std::size_t k = 0; k < camera["keys"].size(); ++k) {
            const Json& key = camera["keys"][k];
            std::string where = "camera.keys[" + std::to_string(k) + "]";
            r.onlyKeys(key, {"frame", "position", "target"}, where);
            scene.camera.keys.push_back({r.number(r.member(key, "frame", where), where + ".frame"),
                                         r.vec3(r.member(key, "position", where), where + ".position"),
                                         r.vec3(r.member(key, "target", where), where + ".target")});
        }
        checkKeyOrder(r, scene.camera.keys, [](std::size_t k) { return "camera.keys[" + std::to_string(k) + "]"; });
    } else {
        scene.camera.keys.push_back({0.0f, r.vec3(r.member(camera, "position", "camera"), "camera.position"),
                                     r.vec3(r.member(camera, "target", "camera"), "camera.target")});
    }
    checkCamera(r, scene.camera, camera.contains("keys"));
    // Everything above names the file and the key; this only backs it up (shared with the
    // procedural scenes).
    scene.validate();
    return scene;
}

Scene loadSceneFile(const std::string& path) {
    std::ifstream in(path);
    if (!in) throw Error("scene file " + path + " cannot be opened");
    std::stringstream text;
    text << in.rdbuf();
    return parseScene(text.str(), path);
}

std::string sceneToJson(const Scene& scene) {
    Json root;
    root["name"] = scene.name;
    Json textures = Json::object();
    for (std::size_t i = 0; i < scene.textures.size(); ++i) {
        const Texture& t = scene.textures[i];
        textures["t" + std::to_string(i)] = {
            {"type", nameOf(kTextureTypes, t.type)}, {"a", vec(t.colorA)}, {"b", vec(t.colorB)}, {"scale", t.scale}};
    }
    root["textures"] = textures;
    Json materials = Json::object();
    for (std::size_t i = 0; i < scene.materials.size(); ++i) {
        const Material& m = scene.materials[i];
        materials["m" + std::to_string(i)] = {{"type", nameOf(kMaterialTypes, m.type)},
                                              {"texture", "t" + std::to_string(m.texture)},
                                              {"roughness", m.roughness},
                                              {"ior", m.ior},
                                              {"emission", vec(m.emission)}};
    }
    root["materials"] = materials;
    Json objects = Json::array();
    for (const Object& o : scene.objects) {
        Json keys = Json::array();
        for (const TransformKey& k : o.keys)
            keys.push_back({{"frame", k.frame},
                            {"translate", vec(k.transform.translate)},
                            {"rotate", vec(k.transform.rotateDegrees)},
                            {"scale", vec(k.transform.scale)}});
        objects.push_back({{"name", o.name},
                           {"shape", nameOf(kShapes, o.shape)},
                           {"material", "m" + std::to_string(o.material)},
                           {"keys", keys}});
    }
    root["objects"] = objects;
    root["environment"] = {{"top", vec(scene.environment.top)}, {"bottom", vec(scene.environment.bottom)}};
    Json cameraKeys = Json::array();
    for (const CameraKey& k : scene.camera.keys)
        cameraKeys.push_back({{"frame", k.frame}, {"position", vec(k.position)}, {"target", vec(k.target)}});
    root["camera"] = {{"fov", scene.camera.fovYDegrees}, {"up", vec(scene.camera.up)}, {"keys", cameraKeys}};
    return root.dump(2);
}

}  // namespace affinity::render
