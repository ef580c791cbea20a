// Scene-source dispatch and the geometry helpers the loaders share.
#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <glm/gtx/matrix_decompose.hpp>
#include <stb/stb_image.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>
#include <cctype>

namespace rtlab::ecs::load {
namespace {

std::string lowercaseExtension(const std::filesystem::path& p) {
    std::string ext = p.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    return ext;
}

}  // namespace

void loadScene(World& world, const std::string& source) {
    constexpr std::string_view kBuiltinPrefix = "builtin:";
    if (source.rfind(kBuiltinPrefix, 0) == 0) {
        loadBuiltinScene(world, source.substr(kBuiltinPrefix.size()));
    } else {
        const std::filesystem::path path(source);
        std::error_code ec;
        if (!std::filesystem::exists(path, ec)) throw InputError(source, "no such file");
        if (std::filesystem::is_directory(path, ec)) throw InputError(source, "is a directory, not a scene file");
        if (!std::filesystem::is_regular_file(path, ec))  // a device or a pipe would be read forever
            throw InputError(source, "not a regular file");
        const std::string ext = lowercaseExtension(path);
        if (ext == ".gltf" || ext == ".glb") loadGltf(world, path);
        else if (ext == ".obj") loadObj(world, path);
        else if (ext == ".ply" || ext == ".fbx") loadWithAssimp(world, path);
        else if (ext == ".json") loadSceneJson(world, path);
        else
            throw InputError(source, "unknown scene type '" + ext +
                                         "' (expected builtin:NAME, .gltf, .glb, .obj, .ply, .fbx or a scene .json)");
    }
    addDefaultCameraAndLight(world);
}

LocalTransform localTransformOf(const mat4& m) {
    LocalTransform t;
    vec3 scale, translation, skew;
    quat rotation;
    vec4 perspective;
    const bool ok = glm::decompose(m, scale, rotation, translation, skew, perspective);
    if (ok && isFinite(scale) && isFinite(translation) && std::isfinite(rotation.w) && std::isfinite(rotation.x) &&
        std::isfinite(rotation.y) && std::isfinite(rotation.z) && glm::length(rotation) > 0.f) {
        t.translation = translation;
        t.rotation = glm::normalize(rotation);
        t.scale = scale;
    } else {
        // Singular (e.g. zero-scale) matrix: keep translation and axis
        // lengths; the rotation cannot be recovered.
        t.translation = vec3(m[3]);
        t.scale = vec3(glm::length(vec3(m[0])), glm::length(vec3(m[1])), glm::length(vec3(m[2])));
    }
    return t;
}

std::vector<MaterialId> commitMaterials(World& world, std::vector<Texture>&& textures,
                                        std::vector<Material>&& materials, std::uint32_t skippedLines,
                                        std::uint32_t skippedPoints, const std::vector<std::string>& warnings) {
    LoadReport& report = world.loadReport();
    report.skippedLinePrimitives += skippedLines;
    report.skippedPointPrimitives += skippedPoints;
    report.warnings.insert(report.warnings.end(), warnings.begin(), warnings.end());
    std::vector<TextureId> textureIds;
    for (Texture& t : textures) textureIds.push_back(world.addTexture(std::move(t)));
    std::vector<MaterialId> materialIds;
    for (Material& m : materials) {
        if (m.baseColorTexture != kNoTexture) m.baseColorTexture = textureIds[m.baseColorTexture];
        materialIds.push_back(world.addMaterial(std::move(m)));
    }
    return materialIds;
}

std::optional<Texture> decodeTexture(const unsigned char* bytes, std::size_t size, const std::string& name,
                                     DecodeBudget& budget) {
    int w = 0, h = 0, channels = 0;
    if (size == 0 || size > std::size_t(std::numeric_limits<int>::max())) return std::nullopt;
    if (!stbi_info_from_memory(bytes, static_cast<int>(size), &w, &h, &channels)) return std::nullopt;
    if (w <= 0 || h <= 0) return std::nullopt;
    if (std::uint64_t(w) * std::uint64_t(h) > kMaxTexturePixels)
        throw InputError(name, "image of " + std::to_string(w) + " x " + std::to_string(h) + " pixels, more than the " +
                                   std::to_string(kMaxTexturePixels) + " a texture may have");
    budget.pixels += std::uint64_t(w) * std::uint64_t(h);
    budget.imageBytes += size;
    if (budget.pixels > budget.pixelLimit())
        throw InputError(name,
                         "the scene's images have " + std::to_string(budget.pixels) + " pixels, more than the " +
                             std::to_string(budget.pixelLimit()) +
                             " it may decode (2^28 + 16 per byte of its compressed images; a scene .json's entries "
                             "share it)");
    stbi_uc* pixels = stbi_load_from_memory(bytes, static_cast<int>(size), &w, &h, &channels, 4);
    if (!pixels) return std::nullopt;
    Texture t;
    t.name = name;
    t.width = w;
    t.height = h;
    t.rgba8.assign(pixels, pixels + std::size_t(w) * std::size_t(h) * 4);
    stbi_image_free(pixels);
    return t;
}

std::optional<Texture> readTextureNamed(const std::filesystem::path& dir, std::string written, DecodeBudget& budget) {
    std::replace(written.begin(), written.end(), '\\', '/');
    const std::filesystem::path asWritten = dir / written;
    const std::filesystem::path beside = dir / std::filesystem::path(written).filename();
    std::vector<std::filesystem::path> candidates{asWritten};
    if (beside.lexically_normal() != asWritten.lexically_normal())
        candidates.push_back(beside);  // each file tried (and its pixels charged) once
    for (const std::filesystem::path& path : candidates) {
        const std::optional<std::vector<unsigned char>> bytes = readRegularFile(path);
        if (!bytes) continue;
        if (std::optional<Texture> t = decodeTexture(bytes->data(), bytes->size(), path.filename().string(), budget))
            return t;
    }
    return std::nullopt;
}

std::optional<std::vector<unsigned char>> readRegularFile(const std::filesystem::path& path, std::uint64_t maxBytes) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) return std::nullopt;  // follows links: /dev/zero is not regular
    const std::uint64_t size = std::filesystem::file_size(path, ec);
    if (ec || size > maxBytes) return std::nullopt;
    std::ifstream f(path, std::ios::binary);
    if (!f) return std::nullopt;
    std::vector<unsigned char> bytes(size);
    f.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size));
    if (static_cast<std::uint64_t>(f.gcount()) != size) return std::nullopt;
    return bytes;
}

bool hasTransparentTexel(const Texture& t) {
    for (std::size_t i = 3; i < t.rgba8.size(); i += 4)
        if (t.rgba8[i] < 255) return true;
    return false;
}

float roughnessFromPhongExponent(float exponent) {
    return std::clamp(std::sqrt(2.f / (std::max(exponent, 0.f) + 2.f)), 0.f, 1.f);
}

std::vector<vec3> generateVertexNormals(const std::vector<vec3>& positions, const std::vector<std::uint32_t>& indices) {
    std::vector<vec3> normals(positions.size(), vec3(0.f));
    for (std::size_t t = 0; t + 2 < indices.size(); t += 3) {
        const std::uint32_t a = indices[t], b = indices[t + 1], c = indices[t + 2];
        if (a >= positions.size() || b >= positions.size() || c >= positions.size()) continue;
        // The cross product's length is twice the area: area weighting for free.
        const vec3 n = glm::cross(positions[b] - positions[a], positions[c] - positions[a]);
        if (!isFinite(n)) continue;
        normals[a] += n;
        normals[b] += n;
        normals[c] += n;
    }
    for (vec3& n : normals) {
        const float len = glm::length(n);
        n = (len > 0.f && std::isfinite(len)) ? n / len : vec3(0.f, 0.f, 1.f);
    }
    return normals;
}

std::size_t degenerateTriangleCount(const MeshAsset& mesh) {
    std::size_t n = 0;
    for (const Geometry& g : mesh.geometries)
        for (std::size_t t = 0; t + 2 < g.indices.size(); t += 3) {
            const vec3& a = g.positions[g.indices[t]];
            const vec3 n3 = glm::cross(g.positions[g.indices[t + 1]] - a, g.positions[g.indices[t + 2]] - a);
            n += n3 == vec3(0.f);
        }
    return n;
}

Aabb worldBounds(const World& world) {
    Aabb bounds;
    world.each<MeshInstance>([&](Entity e, const MeshInstance& inst) {
        if (inst.mesh < world.meshes().size())
            bounds.extend(world.mesh(inst.mesh).bounds().transformed(world.computeInstanceWorldFromObject(e)));
    });
    return bounds;
}

void addDefaultCameraAndLight(World& world) {
    Aabb bounds = worldBounds(world);
    if (bounds.empty()) bounds = Aabb{vec3(-1.f), vec3(1.f)};
    const vec3 center = bounds.center();
    const float radius = std::max(0.5f * glm::length(bounds.extent()), 1e-6f);

    if (!world.alive(world.activeCamera())) {
        // Prefer an existing camera entity; otherwise frame the bounds from +Z.
        Entity found = kNullEntity;
        world.each<Camera>([&](Entity e, const Camera&) {
            if (!found.valid()) found = e;
        });
        if (!found.valid()) {
            const Camera cam{};
            const float distance = radius / std::tan(0.5f * cam.yfov) * 1.1f;
            found = world.create("default camera");
            world.emplace(found,
                          LocalTransform{center + vec3(0.f, 0.f, distance), quat(1.f, 0.f, 0.f, 0.f), vec3(1.f)});
            world.emplace(found, Camera{cam.yfov, distance * 1e-3f, distance + 4.f * radius, 0.f});
        }
        world.setActiveCamera(found);
    }
    if (world.count<Light>() == 0) {
        const Entity sun = world.create("default light");
        // Directional light shining down -Z of a frame rotated to point along (-1,-2,-1).
        const vec3 dir = glm::normalize(vec3(-0.4f, -1.f, -0.6f));
        world.emplace(sun, LocalTransform{vec3(0.f), orientationLookingAlong(dir), vec3(1.f)});
        world.emplace(sun, Light{LightType::Directional, vec3(1.f), 3.f});
    }
}

}  // namespace rtlab::ecs::load
