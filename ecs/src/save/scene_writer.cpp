// OBJ + MTL and PLY writers of rtlab export (scene_writer.hpp).
#include <rtlab/core/error.hpp>
#include <rtlab/core/image.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/save/scene_writer.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace rtlab::ecs::save {
namespace {

// One flattened geometry: world-space positions and normals, UVs, vertex colours, its material.
struct Flat {
    std::vector<vec3> positions, normals;
    std::vector<vec2> uv0;
    std::vector<vec4> colors;
    const std::vector<std::uint32_t>* indices = nullptr;
    MaterialId material = 0;
    std::string object;
};

std::vector<Flat> flatten(const World& world, ExportStats& stats) {
    std::vector<Flat> out;
    world.each<MeshInstance>([&](Entity e, const MeshInstance& inst) {
        if (inst.mesh >= world.meshes().size()) return;
        const MeshAsset& mesh = world.mesh(inst.mesh);
        const mat4 worldFromObject = world.computeInstanceWorldFromObject(e);
        const glm::mat3 normalMatrix = glm::transpose(glm::inverse(glm::mat3(worldFromObject)));
        for (std::size_t gi = 0; gi < mesh.geometries.size(); ++gi) {
            const Geometry& g = mesh.geometries[gi];
            if (g.procedural()) {
                ++stats.proceduralGeometriesLeftOut;
                continue;
            }
            if (g.indices.empty()) continue;
            Flat f;
            f.object = (mesh.name.empty() ? "mesh" + std::to_string(inst.mesh) : mesh.name) + "_" +
                       std::to_string(e.index) + "_" + std::to_string(gi);
            for (char& c : f.object)
                if (c == ' ' || c == '\t' || c == '#') c = '_';
            f.positions.reserve(g.positions.size());
            for (const vec3& p : g.positions) f.positions.push_back(vec3(worldFromObject * vec4(p, 1.f)));
            const std::vector<vec3> normals = g.normals.size() == g.positions.size()
                                                  ? g.normals
                                                  : load::generateVertexNormals(g.positions, g.indices);
            for (const vec3& n : normals) {
                const vec3 w = normalMatrix * n;
                const float len = glm::length(w);
                f.normals.push_back(len > 0.f && std::isfinite(len) ? w / len : vec3(0.f, 0.f, 1.f));
            }
            if (g.uv0.size() == g.positions.size()) f.uv0 = g.uv0;
            if (g.colors.size() == g.positions.size()) f.colors = g.colors;
            f.indices = &g.indices;
            f.material = g.material;
            stats.triangles += g.indices.size() / 3;
            stats.vertices += g.positions.size();
            out.push_back(std::move(f));
        }
    });
    if (stats.triangles == 0) throw InputError("rtlab export", "the scene has no triangles to export");
    return out;
}

// Shortest decimal that reads back as the same float (std::to_chars): exports round-trip exactly.
void put(std::string& s, float v) {
    char buffer[32];
    const auto r = std::to_chars(buffer, buffer + sizeof buffer, v);
    s.append(buffer, r.ptr);
}
void put(std::string& s, std::uint64_t v) {
    char buffer[24];
    const auto r = std::to_chars(buffer, buffer + sizeof buffer, v);
    s.append(buffer, r.ptr);
}

std::string materialName(const World& world, MaterialId id) {
    std::string name(1, 'm');  // (not "m" + to_string: GCC 12 warns falsely, -Wrestrict)
    name += std::to_string(id);
    if (id < world.materials().size() && !world.materials()[id].name.empty()) name += "_" + world.materials()[id].name;
    for (char& c : name)
        if (c == ' ' || c == '\t' || c == '#') c = '_';
    return name;
}

void writeText(const std::filesystem::path& path, const std::string& text) {
    writeFileAtomically(path, [&](const std::filesystem::path& tmp) {
        std::FILE* f = std::fopen(tmp.string().c_str(), "wb");
        if (!f) throw InputError(path.string(), "cannot write");
        const bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
        if (std::fclose(f) != 0 || !ok) throw InputError(path.string(), "cannot write (disk full?)");
    });
}

}  // namespace

ExportStats writeObj(const World& world, const std::filesystem::path& objPath) {
    ExportStats stats;
    const std::vector<Flat> flats = flatten(world, stats);
    std::filesystem::path mtlPath = objPath;
    mtlPath.replace_extension(".mtl");
    // Step: the material library (the OBJ loader's mapping, inverted).
    std::string mtl = "# rtlab export: materials\n";
    for (MaterialId id = 0; id < world.materials().size(); ++id) {
        const Material& m = world.materials()[id];
        mtl += "newmtl " + materialName(world, id) + "\nKd ";
        put(mtl, m.baseColor.r), mtl += ' ', put(mtl, m.baseColor.g), mtl += ' ', put(mtl, m.baseColor.b);
        mtl += "\nd ";
        put(mtl, m.alphaMode == AlphaMode::Blend ? m.baseColor.a : 1.f);
        const float r = std::max(m.roughness, 1e-3f);
        mtl += "\nNs ";
        put(mtl, std::max(2.f / (r * r) - 2.f, 0.f));
        mtl += "\nKe ";
        put(mtl, m.emissive.r), mtl += ' ', put(mtl, m.emissive.g), mtl += ' ', put(mtl, m.emissive.b);
        mtl += "\nNi ";
        put(mtl, m.ior);
        mtl += "\n\n";
    }
    stats.materials = world.materials().size();
    // Step: the geometry, one object per flattened geometry; indices are 1-based and global.
    std::string obj;
    obj.reserve(stats.vertices * 64 + stats.triangles * 40);
    obj += "# rtlab export: " + std::to_string(stats.triangles) + " triangles in world space\nmtllib " +
           mtlPath.filename().string() + "\n";
    std::uint64_t base = 1, uvBase = 1;
    // Vertex colours ("v x y z r g b") on every vertex when some geometry has
    // them (readers keep them only when all vertices have one), white elsewhere.
    const bool colored = std::any_of(flats.begin(), flats.end(), [](const Flat& f) { return !f.colors.empty(); });
    for (const Flat& f : flats) {
        obj += "o " + f.object + "\n";
        for (std::size_t v = 0; v < f.positions.size(); ++v) {
            const vec3& p = f.positions[v];
            obj += "v ", put(obj, p.x), obj += ' ', put(obj, p.y), obj += ' ', put(obj, p.z);
            if (colored) {
                const vec4 c = f.colors.empty() ? vec4(1.f) : f.colors[v];
                obj += ' ', put(obj, c.r), obj += ' ', put(obj, c.g), obj += ' ', put(obj, c.b);
            }
            obj += '\n';
        }
        for (const vec3& n : f.normals) {
            obj += "vn ", put(obj, n.x), obj += ' ', put(obj, n.y), obj += ' ', put(obj, n.z), obj += '\n';
        }
        const bool uvs = !f.uv0.empty();
        for (const vec2& t : f.uv0) obj += "vt ", put(obj, t.x), obj += ' ', put(obj, 1.f - t.y), obj += '\n';
        obj += "usemtl " + materialName(world, f.material) + "\n";
        const std::vector<std::uint32_t>& ix = *f.indices;
        for (std::size_t t = 0; t + 2 < ix.size(); t += 3) {
            obj += 'f';
            for (int k = 0; k < 3; ++k) {
                obj += ' ';
                put(obj, base + ix[t + k]);
                obj += '/';
                if (uvs) put(obj, uvBase + ix[t + k]);
                obj += '/';
                put(obj, base + ix[t + k]);
            }
            obj += '\n';
        }
        base += f.positions.size();
        if (uvs) uvBase += f.uv0.size();
    }
    writeText(mtlPath, mtl);
    writeText(objPath, obj);
    return stats;
}

ExportStats writePly(const World& world, const std::filesystem::path& plyPath) {
    ExportStats stats;
    const std::vector<Flat> flats = flatten(world, stats);
    stats.materials = world.materials().size();
    std::string out = "ply\nformat binary_little_endian 1.0\ncomment rtlab export: world space\nelement vertex " +
                      std::to_string(stats.vertices) +
                      "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float "
                      "ny\nproperty float nz\nelement face " +
                      std::to_string(stats.triangles) +
                      "\nproperty list uchar uint vertex_indices\nproperty uint material\nend_header\n";
    auto raw = [&out](const void* p, std::size_t n) { out.append(static_cast<const char*>(p), n); };
    for (const Flat& f : flats)
        for (std::size_t i = 0; i < f.positions.size(); ++i) {
            raw(&f.positions[i], 12);
            raw(&f.normals[i], 12);
        }
    std::uint32_t base = 0;
    for (const Flat& f : flats) {
        const std::vector<std::uint32_t>& ix = *f.indices;
        for (std::size_t t = 0; t + 2 < ix.size(); t += 3) {
            const unsigned char three = 3;
            raw(&three, 1);
            for (int k = 0; k < 3; ++k) {
                const std::uint32_t v = base + ix[t + k];
                raw(&v, 4);
            }
            const std::uint32_t m = f.material;
            raw(&m, 4);
        }
        base += static_cast<std::uint32_t>(f.positions.size());
    }
    writeText(plyPath, out);
    return stats;
}

}  // namespace rtlab::ecs::save
