// Built-in scenes. `showcase` exercises every effect; `cornell` is diffuse
// only with one area light (the scene that needs few passes). The scalable
// scenes (terrain, forest, hairball, slivers) live in scalable_scenes.cpp; this file
// parses every builtin source string, "NAME" or "NAME?key=value&key=value".
#include "builtin_common.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <algorithm>
#include <charconv>
#include <limits>

namespace rtlab::ecs::load {
namespace builtin {

Material diffuse(const std::string& name, const vec3& albedo) {
    Material m;
    m.name = name;
    m.baseColor = vec4(albedo, 1.f);
    m.roughness = 1.f;
    return m;
}

Entity place(World& world, const std::string& name, MeshId mesh, const vec3& t, const quat& r, const vec3& s) {
    const Entity e = world.create(name);
    world.emplace(e, LocalTransform{t, r, s});
    world.emplace(e, MeshInstance{mesh});
    return e;
}

Entity addLight(World& world, const std::string& name, const Light& light, const vec3& position,
                const vec3& direction) {
    const Entity e = world.create(name);
    world.emplace(e, LocalTransform{position, orientationLookingAlong(direction), vec3(1.f)});
    world.emplace(e, light);
    return e;
}

Entity addCamera(World& world, const vec3& position, const vec3& target, float yfov, float zfar) {
    const Entity e = world.create("camera");
    world.emplace(e, LocalTransform{position, orientationLookingAlong(target - position), vec3(1.f)});
    world.emplace(e, Camera{yfov, 0.01f, zfar, 0.f});
    world.setActiveCamera(e);
    return e;
}

}  // namespace builtin

namespace {

using namespace builtin;

// A closed box seen from inside: the room's walls face inwards.
Geometry makeRoomShell(const vec3& size, MaterialId material) {
    Geometry g = makeBox(size, material);
    for (std::size_t i = 0; i < g.indices.size(); i += 3) std::swap(g.indices[i + 1], g.indices[i + 2]);
    for (vec3& n : g.normals) n = -n;
    return g;
}

// Leaf cut-out: opaque inside a few ellipses, alpha 0 elsewhere (alpha mask).
Texture makeFoliageTexture() {
    Texture t;
    t.name = "foliage";
    t.width = t.height = 64;
    t.rgba8.resize(64 * 64 * 4);
    const vec2 leaves[5] = {{0.3f, 0.3f}, {0.7f, 0.35f}, {0.5f, 0.6f}, {0.25f, 0.75f}, {0.75f, 0.75f}};
    for (int y = 0; y < 64; ++y)
        for (int x = 0; x < 64; ++x) {
            const vec2 uv((x + 0.5f) / 64.f, (y + 0.5f) / 64.f);
            bool inside = false;
            for (const vec2& c : leaves) {
                const vec2 d = (uv - c) / vec2(0.16f, 0.09f);
                inside = inside || glm::dot(d, d) < 1.f;
            }
            std::uint8_t* px = &t.rgba8[(y * 64 + x) * 4];
            px[0] = 60;
            px[1] = static_cast<std::uint8_t>(120 + 60 * uv.y);
            px[2] = 40;
            px[3] = inside ? 255 : 0;
        }
    return t;
}

// A flag-like grid whose single morph target is a travelling wave.
MeshAsset makeWavingCloth(MaterialId material) {
    Geometry g = makeGrid(1.6f, 24, material);
    MorphTarget wave;
    for (const vec3& p : g.positions)
        wave.positionDeltas.emplace_back(0.f, 0.25f * std::sin(4.f * p.x + 3.f * p.z), 0.f);
    g.restPositions = g.positions;
    g.restNormals = g.normals;
    g.morphTargets.push_back(std::move(wave));
    return makeMesh("waving cloth", std::move(g));
}

AnimationChannel linearChannel(Entity target, AnimationPath path, std::vector<float> times, std::vector<float> values,
                               std::uint32_t components) {
    AnimationChannel c;
    c.target = target;
    c.path = path;
    c.interpolation = Interpolation::Linear;
    c.times = std::move(times);
    c.values = std::move(values);
    c.componentsPerKey = components;
    return c;
}

void buildShowcase(World& world) {
    world.settings().name = "showcase";
    const vec3 room(8.f, 5.f, 10.f);

    // Step: materials.
    const MaterialId walls = world.addMaterial(diffuse("walls", vec3(0.75f, 0.72f, 0.68f)));
    Material floor = diffuse("glossy floor", vec3(0.35f, 0.3f, 0.28f));
    floor.roughness = 0.1f;
    const MaterialId floorMat = world.addMaterial(floor);
    Material mirror;
    mirror.name = "mirror";
    mirror.baseColor = vec4(0.95f, 0.95f, 0.95f, 1.f);
    mirror.metallic = 1.f;
    mirror.roughness = 0.f;
    const MaterialId mirrorMat = world.addMaterial(mirror);
    const MaterialId red = world.addMaterial(diffuse("red diffuse", vec3(0.7f, 0.12f, 0.1f)));
    const MaterialId blue = world.addMaterial(diffuse("blue diffuse", vec3(0.1f, 0.2f, 0.7f)));
    const MaterialId clothMat = world.addMaterial(diffuse("cloth", vec3(0.8f, 0.6f, 0.2f)));
    Material glass;
    glass.name = "glass";
    glass.baseColor = vec4(1.f);
    glass.roughness = 0.f;
    glass.transmission = 1.f;
    glass.ior = 1.5f;
    glass.attenuationColor = vec3(0.6f, 0.9f, 0.8f);
    glass.attenuationDistance = 1.f;
    const MaterialId glassMat = world.addMaterial(glass);
    Material leaves = diffuse("foliage", vec3(1.f));
    leaves.baseColorTexture = world.addTexture(makeFoliageTexture());
    leaves.alphaMode = AlphaMode::Mask;
    leaves.alphaCutoff = 0.5f;
    leaves.doubleSided = true;
    const MaterialId leafMat = world.addMaterial(leaves);

    // Step: geometry. The room shell and floor are separate meshes so the
    // floor can be glossy.
    Geometry shell = makeRoomShell(room, walls);
    place(world, "room", world.addMesh(makeMesh("room shell", std::move(shell))), vec3(0.f, 0.5f * room.y, 0.f));
    place(world, "floor", world.addMesh(makeMesh("floor", makeGrid(room.x - 0.02f, 1, floorMat))),
          vec3(0.f, 0.001f, 0.f), quat(1, 0, 0, 0), vec3(1.f, 1.f, (room.z - 0.02f) / (room.x - 0.02f)));
    place(world, "mirror sphere", world.addMesh(makeMesh("sphere", makeIcosphere(0.8f, 4, mirrorMat))),
          vec3(-1.8f, 0.8f, -2.0f));
    place(world, "red box", world.addMesh(makeMesh("box", makeBox(vec3(1.2f, 1.6f, 1.2f), red))),
          vec3(2.2f, 0.8f, -2.5f), glm::angleAxis(0.4f, vec3(0, 1, 0)));
    place(world, "glass block", world.addMesh(makeMesh("glass block", makeBox(vec3(1.f, 1.4f, 0.6f), glassMat))),
          vec3(0.4f, 0.7f, -0.6f), glm::angleAxis(-0.3f, vec3(0, 1, 0)));
    place(world, "foliage", world.addMesh(makeMesh("foliage quad", makeQuad(1.6f, 1.6f, leafMat))),
          vec3(-3.0f, 1.4f, 0.8f), glm::angleAxis(0.9f, vec3(0, 1, 0)));

    // Rigid motion: a blue box sliding back and forth (TLAS-only updates).
    const Entity mover = place(world, "moving box", world.addMesh(makeMesh("small box", makeBox(vec3(0.6f), blue))),
                               vec3(-1.5f, 0.3f, 1.2f));
    // Deformation: a waving cloth driven by a morph weight (BLAS refits).
    const Entity cloth = place(world, "waving cloth", world.addMesh(makeWavingCloth(clothMat)), vec3(2.0f, 1.8f, 0.5f),
                               glm::angleAxis(0.5f * kPi, vec3(1, 0, 0)) * glm::angleAxis(0.3f, vec3(0, 0, 1)));
    world.emplace(cloth, MorphWeights{{0.f}});
    AnimationClip clip;
    clip.name = "showcase motion";
    clip.channels.push_back(linearChannel(mover, AnimationPath::Translation, {0.f, 1.f, 2.f},
                                          {-1.5f, 0.3f, 1.2f, 1.0f, 0.3f, 1.8f, -1.5f, 0.3f, 1.2f}, 3));
    clip.channels.push_back(linearChannel(cloth, AnimationPath::Weights, {0.f, 1.f, 2.f}, {0.f, 1.f, 0.f}, 1));
    world.addAnimation(std::move(clip));

    // Step: lights — one rectangle area light on the ceiling, several points.
    Light rect{LightType::Rect, vec3(1.f, 0.95f, 0.85f), 12.f};
    rect.size = vec2(2.0f, 1.2f);
    addLight(world, "ceiling panel", rect, vec3(0.f, room.y - 0.01f, -0.5f));
    const vec3 pointColors[3] = {{1.f, 0.6f, 0.3f}, {0.4f, 0.6f, 1.f}, {0.8f, 1.f, 0.6f}};
    const vec3 pointPositions[3] = {{-3.f, 3.5f, -3.5f}, {3.f, 3.0f, -3.5f}, {0.f, 2.5f, 3.5f}};
    for (int i = 0; i < 3; ++i) {
        Light point{LightType::Point, pointColors[i], 6.f};
        point.range = 12.f;
        addLight(world, "point light " + std::to_string(i), point, pointPositions[i]);
    }

    // Step: a procedural fog volume hovering in the back of the room.
    const Aabb fogBounds{vec3(-3.5f, 0.2f, -4.6f), vec3(3.5f, 3.2f, -1.2f)};
    const VolumeId fog = world.addVolumeGrid(VolumeGrid::makeProceduralFog(fogBounds, 0.1f, 0.6f, 7u));
    const Entity fogEntity = world.create("fog");
    world.emplace(fogEntity, Volume{fog, 1.f, vec3(0.85f)});

    addCamera(world, vec3(0.f, 2.2f, 4.6f), vec3(0.f, 1.2f, -2.f), 1.05f);
}

void buildCornell(World& world) {
    world.settings().name = "cornell";
    const MaterialId white = world.addMaterial(diffuse("white", vec3(0.73f)));
    const MaterialId red = world.addMaterial(diffuse("red", vec3(0.63f, 0.065f, 0.05f)));
    const MaterialId green = world.addMaterial(diffuse("green", vec3(0.14f, 0.45f, 0.091f)));
    const float s = 2.f;  // room side
    const MeshId wall = world.addMesh(makeMesh("wall", makeGrid(s, 1, white)));
    const MeshId redWall = world.addMesh(makeMesh("red wall", makeGrid(s, 1, red)));
    const MeshId greenWall = world.addMesh(makeMesh("green wall", makeGrid(s, 1, green)));
    const vec3 x(1, 0, 0), z(0, 0, 1);
    place(world, "floor", wall, vec3(0.f));
    place(world, "ceiling", wall, vec3(0.f, s, 0.f), glm::angleAxis(kPi, x));
    place(world, "back wall", wall, vec3(0.f, 0.5f * s, -0.5f * s), glm::angleAxis(0.5f * kPi, x));
    place(world, "left wall", redWall, vec3(-0.5f * s, 0.5f * s, 0.f), glm::angleAxis(-0.5f * kPi, z));
    place(world, "right wall", greenWall, vec3(0.5f * s, 0.5f * s, 0.f), glm::angleAxis(0.5f * kPi, z));
    place(world, "tall box", world.addMesh(makeMesh("tall box", makeBox(vec3(0.6f, 1.2f, 0.6f), white))),
          vec3(-0.35f, 0.6f, -0.3f), glm::angleAxis(0.3f, vec3(0, 1, 0)));
    place(world, "short box", world.addMesh(makeMesh("short box", makeBox(vec3(0.6f), white))), vec3(0.4f, 0.3f, 0.3f),
          glm::angleAxis(-0.3f, vec3(0, 1, 0)));
    Light panel{LightType::Rect, vec3(1.f, 0.85f, 0.6f), 15.f};
    panel.size = vec2(0.5f, 0.4f);
    addLight(world, "ceiling light", panel, vec3(0.f, s - 0.005f, 0.f));
    addCamera(world, vec3(0.f, 1.f, 3.9f), vec3(0.f, 1.f, 0.f), 0.69f);
}

struct ParameterSpec {
    const char* key;
    std::uint32_t defaultValue, min, max;
};

struct BuiltinScene {
    const char* name;
    void (*build)(World&, const Parameters&);
    std::vector<ParameterSpec> parameters;
};

const std::vector<BuiltinScene>& builtinScenes() {
    constexpr std::uint32_t kMaxSeed = std::numeric_limits<std::uint32_t>::max();
    static const std::vector<BuiltinScene> scenes = {
        {"showcase", [](World& w, const Parameters&) { buildShowcase(w); }, {}},
        {"cornell", [](World& w, const Parameters&) { buildCornell(w); }, {}},
        {"terrain", buildTerrain, {{"triangles", 100000, 1000, 10000000}, {"seed", 0, 0, kMaxSeed}}},
        {"forest", buildForest, {{"instances", 1000, 1, 1000000}, {"seed", 0, 0, kMaxSeed}}},
        {"hairball", buildHairball, {{"triangles", 100000, 1000, 10000000}, {"seed", 0, 0, kMaxSeed}}},
        {"slivers", buildSlivers, {{"triangles", 100000, 1000, 10000000}, {"seed", 0, 0, kMaxSeed}}},
    };
    return scenes;
}

std::string joined(const std::vector<std::string>& items) {
    std::string s;
    for (const std::string& item : items) s += (s.empty() ? "" : ", ") + item;
    return s;
}

// A non-negative integer: decimal digits, optionally with a decimal exponent
// ("1e6"). Returns false on anything else or on overflow past 2^32 - 1.
bool parseInteger(const std::string& text, std::uint64_t& value) {
    const std::size_t e = text.find_first_of("eE");
    const std::string mantissa = text.substr(0, e);
    const auto digitsOnly = [](const std::string& t) {
        return !t.empty() && t.size() <= 10 && t.find_first_not_of("0123456789") == std::string::npos;
    };
    if (!digitsOnly(mantissa)) return false;
    std::from_chars(mantissa.data(), mantissa.data() + mantissa.size(), value);
    if (e != std::string::npos) {
        const std::string exponent = text.substr(e + 1);
        if (!digitsOnly(exponent) || exponent.size() > 2) return false;
        for (int i = std::stoi(exponent); i > 0 && value != 0; --i)
            if ((value *= 10) > std::numeric_limits<std::uint32_t>::max()) return false;
    }
    return value <= std::numeric_limits<std::uint32_t>::max();
}

// "key=value&key=value" checked against the scene's accepted parameters.
Parameters parseParameters(const std::string& source, const BuiltinScene& scene, const std::string& query) {
    std::vector<std::string> accepted;
    for (const ParameterSpec& spec : scene.parameters) accepted.push_back(spec.key);
    const std::string acceptedText = accepted.empty() ? "builtin:" + std::string(scene.name) + " takes no parameters"
                                                      : "accepted: " + joined(accepted);
    Parameters values;
    std::size_t begin = 0;
    while (begin <= query.size()) {
        const std::size_t end = std::min(query.find('&', begin), query.size());
        const std::string item = query.substr(begin, end - begin);
        begin = end + 1;
        const std::size_t eq = item.find('=');
        if (eq == std::string::npos || eq == 0)
            throw InputError(source, "expected key=value, got '" + item + "' (" + acceptedText + ")");
        const std::string key = item.substr(0, eq), text = item.substr(eq + 1);
        const auto spec = std::find_if(scene.parameters.begin(), scene.parameters.end(),
                                       [&](const ParameterSpec& p) { return key == p.key; });
        if (spec == scene.parameters.end())
            throw InputError(source, "unknown parameter '" + key + "' (" + acceptedText + ")");
        if (values.count(key)) throw InputError(source, "parameter '" + key + "' given twice");
        const std::string range = std::to_string(spec->min) + " to " + std::to_string(spec->max);
        std::uint64_t value = 0;
        if (!parseInteger(text, value))
            throw InputError(source,
                             "parameter '" + key + "' has value '" + text + "', expected an integer from " + range);
        if (value < spec->min || value > spec->max)
            throw InputError(source,
                             "parameter '" + key + "' is " + std::to_string(value) + ", out of range (" + range + ")");
        values[key] = static_cast<std::uint32_t>(value);
    }
    return values;
}

}  // namespace

std::vector<std::string> builtinSceneNames() {
    std::vector<std::string> names;
    for (const BuiltinScene& scene : builtinScenes()) names.push_back(scene.name);
    return names;
}

namespace {

// The scene `nameAndParameters` names and its parameters, checked.
std::pair<const BuiltinScene*, Parameters> parseBuiltinSource(const std::string& nameAndParameters) {
    const std::string source = "builtin:" + nameAndParameters;
    const std::size_t question = nameAndParameters.find('?');
    const std::string name = nameAndParameters.substr(0, question);
    const auto scene = std::find_if(builtinScenes().begin(), builtinScenes().end(),
                                    [&](const BuiltinScene& s) { return name == s.name; });
    if (scene == builtinScenes().end())
        throw InputError(source, "unknown builtin scene (available: " + joined(builtinSceneNames()) + ")");
    Parameters values;
    if (question != std::string::npos) values = parseParameters(source, *scene, nameAndParameters.substr(question + 1));
    return {&*scene, std::move(values)};
}

}  // namespace

void checkBuiltinScene(const std::string& nameAndParameters) { parseBuiltinSource(nameAndParameters); }

void loadBuiltinScene(World& world, const std::string& nameAndParameters) {
    auto [scene, values] = parseBuiltinSource(nameAndParameters);
    world.settings().parameters.clear();
    for (const ParameterSpec& spec : scene->parameters) {
        values.emplace(spec.key, spec.defaultValue);  // keeps a given value
        world.settings().parameters.emplace_back(spec.key, values.at(spec.key));
    }
    scene->build(world, values);
}

}  // namespace rtlab::ecs::load
