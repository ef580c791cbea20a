// Wavefront OBJ + MTL through tinyobjloader 2.0 (docs/scene-format.md, "OBJ and MTL"):
// polygons triangulated here by ear clipping (concave ones too), objects and
// groups kept as meshes, per-face materials as geometries, normals computed
// where the file has none, MTL colours, shininess, dissolve, emission, index
// of refraction, the base-colour map and map_d (alpha channels as alpha masks),
// vertex colours.
// A missing .mtl or texture is a warning (World::loadReport) and a default
// material; points and lines are skipped with a warning; anything malformed
// is an InputError naming the file.
#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <tiny_obj_loader.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <map>
#include <utility>
#include <optional>
#include <sstream>
#include <filesystem>
#include <functional>
#include <unordered_map>

namespace rtlab::ecs::load {
namespace {

std::string firstLine(const std::string& text) {
    std::string line = text.substr(0, text.find('\n'));
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    return line.empty() ? "not a readable OBJ file" : line;
}

// MTL's map_d as the base colour texture's alpha: the map's alpha channel
// where it has one, else its grey level (its red channel), nearest-resampled
// onto the base texture's texels (multiplying any alpha that has); where the
// material has no base texture, a white one of the map's size (the Kd factor
// still colours it).
Texture withDissolveMap(std::optional<Texture> base, const Texture& dissolve) {
    if (!base) {
        base = dissolve;
        std::fill(base->rgba8.begin(), base->rgba8.end(), std::uint8_t{255});
    }
    bool ownAlpha = false;
    for (std::size_t i = 3; i < dissolve.rgba8.size(); i += 4) ownAlpha |= dissolve.rgba8[i] != 255;
    const int channel = ownAlpha ? 3 : 0;
    for (int y = 0; y < base->height; ++y) {
        const int sy = static_cast<int>((static_cast<std::int64_t>(y) * dissolve.height) / base->height);
        for (int x = 0; x < base->width; ++x) {
            const int sx = static_cast<int>((static_cast<std::int64_t>(x) * dissolve.width) / base->width);
            const std::uint8_t a = dissolve.rgba8[(std::size_t(sy) * dissolve.width + sx) * 4 + channel];
            std::uint8_t& out = base->rgba8[(std::size_t(y) * base->width + x) * 4 + 3];
            out = static_cast<std::uint8_t>((unsigned(out) * a + 127) / 255);
        }
    }
    return std::move(*base);
}

// Triangles of a simple polygon (indices into `p`, its corners in order) by
// ear clipping in the plane of its Newell normal; a polygon ear clipping
// cannot finish (self-intersecting, degenerate) falls back to a fan.
void triangulate(const std::vector<vec3>& p, std::vector<std::uint32_t>& out) {
    const std::size_t n = p.size();
    if (n < 3) return;
    if (n == 3) {
        out.insert(out.end(), {0u, 1u, 2u});
        return;
    }
    // Step: the plane, by the Newell normal; project onto its two other axes.
    vec3 normal(0.f);
    for (std::size_t i = 0; i < n; ++i) {
        const vec3& a = p[i];
        const vec3& b = p[(i + 1) % n];
        normal += vec3((a.y - b.y) * (a.z + b.z), (a.z - b.z) * (a.x + b.x), (a.x - b.x) * (a.y + b.y));
    }
    const vec3 m = glm::abs(normal);
    const int drop = m.x >= m.y && m.x >= m.z ? 0 : (m.y >= m.z ? 1 : 2);
    const int u = drop == 0 ? 1 : 0, v = drop == 2 ? 1 : 2;
    const float sign = normal[drop] >= 0.f ? 1.f : -1.f;
    std::vector<vec2> q(n);
    for (std::size_t i = 0; i < n; ++i) q[i] = vec2(p[i][u], p[i][v] * sign);
    auto cross2 = [](const vec2& a, const vec2& b, const vec2& c) {
        return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
    };
    // Step: clip convex corners whose triangle holds no other corner.
    std::vector<std::uint32_t> left(n);
    for (std::size_t i = 0; i < n; ++i) left[i] = static_cast<std::uint32_t>(i);
    const std::size_t first = out.size();
    std::size_t guard = 0;
    while (left.size() > 3 && guard < 2 * n * n) {
        bool clipped = false;
        for (std::size_t i = 0; i < left.size() && !clipped; ++i, ++guard) {
            const std::uint32_t a = left[(i + left.size() - 1) % left.size()], b = left[i],
                                c = left[(i + 1) % left.size()];
            if (cross2(q[a], q[b], q[c]) <= 0.f) continue;  // reflex or flat corner
            bool inside = false;
            for (const std::uint32_t k : left) {
                if (k == a || k == b || k == c) continue;
                if (cross2(q[a], q[b], q[k]) >= 0.f && cross2(q[b], q[c], q[k]) >= 0.f &&
                    cross2(q[c], q[a], q[k]) >= 0.f) {
                    inside = true;
                    break;
                }
            }
            if (inside) continue;
            out.insert(out.end(), {a, b, c});
            left.erase(left.begin() + static_cast<std::ptrdiff_t>(i));
            clipped = true;
        }
        if (!clipped) break;
    }
    if (left.size() == 3) {
        out.insert(out.end(), {left[0], left[1], left[2]});
        return;
    }
    out.resize(first);  // ear clipping failed: a fan over the corners
    for (std::uint32_t i = 1; i + 1 < n; ++i) out.insert(out.end(), {0u, i, i + 1});
}

// The most corners a face rtlab triangulates itself may have: tinyobjloader
// keeps a face's corner count in a byte (a 300-corner face would silently
// become 44 corners and shift every face after it), and ear clipping costs up
// to 2 n^3 steps. A file with a bigger face is triangulated by tinyobjloader.
constexpr int kMaxFaceCorners = 255;

// A face corner's (v, vn + 1, vt + 1), every index whole (a packing into one
// 64-bit word once merged corners of files with millions of vertices).
struct CornerKey {
    std::uint64_t vertexAndNormal;
    std::uint32_t texcoord;
    bool operator==(const CornerKey&) const = default;
};
struct CornerKeyHash {
    std::size_t operator()(const CornerKey& k) const {
        return std::hash<std::uint64_t>{}(k.vertexAndNormal * 0x9e3779b97f4a7c15ull ^ k.texcoord);
    }
};

}  // namespace

std::vector<Entity> loadObj(World& world, const std::filesystem::path& path, Entity parent) {
    const std::string where = path.string();
    // Step: parse (tinyobjloader), the .mtl beside the file; polygons kept whole.
    tinyobj::ObjReaderConfig config;
    config.triangulate = false;
    std::string bigFace;  // the first face of more than kMaxFaceCorners, if any
    config.vertex_color = false;
    config.mtl_search_path = path.parent_path().string();
    {
        // What tinyobjloader accepts silently: UTF-16 text (a byte-order mark;
        // it would read "no faces") and faces of fewer than three corners.
        std::ifstream f(path, std::ios::binary);
        unsigned char bom[2] = {0, 0};
        f.read(reinterpret_cast<char*>(bom), 2);
        if ((bom[0] == 0xfe && bom[1] == 0xff) || (bom[0] == 0xff && bom[1] == 0xfe))
            throw InputError(where, "UTF-16 text: rtlab reads OBJ files as ASCII or UTF-8 (convert it, e.g. iconv)");
        f.clear();
        f.seekg(0);
        std::string line;
        for (std::size_t number = 1; std::getline(f, line); ++number) {
            std::size_t at = line.find_first_not_of(" \t");
            if (at != std::string::npos && line.compare(at, 7, "mtllib ") == 0) {
                // tinyobjloader reads what it names to the end: never a device or a pipe.
                std::istringstream names(line.substr(at + 7));
                std::error_code ec;
                for (std::string name; names >> name;) {
                    const std::filesystem::path mtl = path.parent_path() / name;
                    if (std::filesystem::exists(mtl, ec) && !std::filesystem::is_regular_file(mtl, ec))
                        throw InputError(
                            where, "line " + std::to_string(number) + ": mtllib '" + name + "' is not a regular file");
                }
                continue;
            }
            if (at == std::string::npos || line[at] != 'f' ||
                (at + 1 < line.size() && !std::isspace(static_cast<unsigned char>(line[at + 1]))))
                continue;
            std::istringstream corners(line.substr(at + 1));
            std::string corner;
            int count = 0;
            while (corners >> corner && corner[0] != '#') ++count;
            if (count < 3)
                throw InputError(where, "line " + std::to_string(number) + ": a face of " + std::to_string(count) +
                                            " corner(s) (at least 3)");
            if (count > kMaxFaceCorners && !config.triangulate) {
                config.triangulate = true;  // every face, by tinyobjloader
                bigFace = "line " + std::to_string(number) + ": a face of " + std::to_string(count) + " corners";
            }
        }
    }
    tinyobj::ObjReader reader;
    if (!reader.ParseFromFile(path.string(), config)) throw InputError(where, firstLine(reader.Error()));
    std::vector<std::string> warnings;
    if (config.triangulate)
        warnings.push_back(where + ": " + bigFace + ": more than " + std::to_string(kMaxFaceCorners) +
                           ", so every face is triangulated by tinyobjloader, not by rtlab's ear clipping");
    {
        std::istringstream lines(reader.Warning());
        std::string line;
        while (std::getline(lines, line))
            if (!line.empty()) warnings.push_back(where + ": " + line);
    }
    const tinyobj::attrib_t& attrib = reader.GetAttrib();
    const std::size_t vertexCount = attrib.vertices.size() / 3, normalCount = attrib.normals.size() / 3,
                      uvCount = attrib.texcoords.size() / 2;
    // Vertex colours ("v x y z r g b") only when every vertex has one
    // (tinyobjloader keeps them then); finite, clamped to [0, 1].
    const bool colored = vertexCount > 0 && attrib.colors.size() == attrib.vertices.size();
    if (colored)
        for (const float f : attrib.colors)
            if (!std::isfinite(f)) throw InputError(where, "a vertex colour is not a finite number");
    for (const float f : attrib.vertices)
        if (!std::isfinite(f)) throw InputError(where, "a vertex coordinate is not a finite number");

    // Step: materials (MTL -> rtlab, docs/scene-format.md), textures staged.
    std::vector<Texture> textures;
    std::vector<Material> materials;
    DecodeBudget budget;
    // Each (map_Kd, map_d) pair read and decoded once, however many materials name it.
    std::map<std::pair<std::string, std::string>, std::optional<TextureId>> textureOf;
    std::vector<bool> cutsOut;  // per staged texture: some texel not opaque
    const auto stageTexture = [&](const tinyobj::material_t& mt) -> std::optional<TextureId> {
        const std::string& alpha = mt.alpha_texname != mt.diffuse_texname ? mt.alpha_texname : std::string();
        const auto key = std::make_pair(mt.diffuse_texname, alpha);
        if (const auto it = textureOf.find(key); it != textureOf.end()) return it->second;
        std::optional<Texture> t;
        try {
            if (!mt.diffuse_texname.empty()) {
                t = readTextureNamed(path.parent_path(), mt.diffuse_texname, budget);
                if (!t)
                    warnings.push_back(where + ": texture " + mt.diffuse_texname +
                                       " not found or not readable, left out");
            }
            if (!alpha.empty()) {  // the same file as map_Kd: its alpha already counts
                const std::optional<Texture> dissolve = readTextureNamed(path.parent_path(), alpha, budget);
                if (!dissolve)
                    warnings.push_back(where + ": texture " + alpha + " (map_d) not found or not readable, left out");
                else t = withDissolveMap(std::move(t), *dissolve);
            }
        } catch (const InputError& e) {
            throw InputError(where, e.what());  // the texture's problem, named within the OBJ
        }
        std::optional<TextureId> id;
        if (t) {
            id = static_cast<TextureId>(textures.size());
            cutsOut.push_back(hasTransparentTexel(*t));
            textures.push_back(std::move(*t));
        }
        return textureOf[key] = id;
    };
    for (const tinyobj::material_t& mt : reader.GetMaterials()) {
        Material m;
        m.name = mt.name;
        m.baseColor = vec4(mt.diffuse[0], mt.diffuse[1], mt.diffuse[2], std::clamp(float(mt.dissolve), 0.f, 1.f));
        m.emissive = vec3(mt.emission[0], mt.emission[1], mt.emission[2]);
        // Phong exponent -> roughness (the Blinn-Phong / GGX correspondence alpha = sqrt(2 / (Ns + 2))).
        m.roughness = roughnessFromPhongExponent(float(mt.shininess));
        if (mt.ior > 0.f) m.ior = mt.ior;
        if (m.baseColor.a < 1.f) m.alphaMode = AlphaMode::Blend;
        if (const std::optional<TextureId> id = stageTexture(mt)) {
            if (cutsOut[*id]) m.alphaMode = AlphaMode::Mask;  // cut-outs (foliage, chains)
            m.baseColorTexture = *id;
        }
        materials.push_back(std::move(m));
    }
    const MaterialId defaultMaterial = static_cast<MaterialId>(materials.size());
    materials.push_back(Material{"default"});

    // Step: each shape (object or group) a mesh; its faces by material a geometry.
    std::vector<MeshAsset> meshes;
    std::uint32_t skippedLines = 0, skippedPoints = 0;
    for (const tinyobj::shape_t& shape : reader.GetShapes()) {
        skippedLines += static_cast<std::uint32_t>(shape.lines.num_line_vertices.size());
        skippedPoints += static_cast<std::uint32_t>(shape.points.indices.size());
        const tinyobj::mesh_t& mesh = shape.mesh;
        if (mesh.num_face_vertices.empty()) continue;
        std::map<MaterialId, std::size_t> geometryOf;
        MeshAsset asset;
        asset.name = shape.name.empty() ? "object " + std::to_string(meshes.size()) : shape.name;
        struct Build {
            std::unordered_map<CornerKey, std::uint32_t, CornerKeyHash> vertexOf;  // (v, vn, vt) -> vertex
            bool allNormals = true, allUvs = true;
        };
        std::vector<Build> builds;
        std::size_t corner = 0;
        std::vector<vec3> polygon;
        std::vector<std::uint32_t> polygonVertices, triangles;
        for (std::size_t face = 0; face < mesh.num_face_vertices.size(); ++face) {
            const std::size_t n = mesh.num_face_vertices[face];
            if (corner + n > mesh.indices.size()) throw InputError(where, "a face has more corners than indices");
            const int mid = face < mesh.material_ids.size() ? mesh.material_ids[face] : -1;
            const MaterialId material =
                mid >= 0 && std::size_t(mid) < reader.GetMaterials().size() ? MaterialId(mid) : defaultMaterial;
            auto [it, added] = geometryOf.try_emplace(material, asset.geometries.size());
            if (added) {
                asset.geometries.emplace_back();
                asset.geometries.back().material = material;
                builds.emplace_back();
            }
            Geometry& g = asset.geometries[it->second];
            Build& b = builds[it->second];
            polygon.clear();
            polygonVertices.clear();
            for (std::size_t k = 0; k < n; ++k) {
                const tinyobj::index_t& ix = mesh.indices[corner + k];
                if (ix.vertex_index < 0 || std::size_t(ix.vertex_index) >= vertexCount)
                    throw InputError(where, "face " + std::to_string(face + 1) + " of " + asset.name +
                                                " refers to vertex " + std::to_string(ix.vertex_index + 1) + " of " +
                                                std::to_string(vertexCount));
                if (ix.normal_index >= 0 && std::size_t(ix.normal_index) >= normalCount)
                    throw InputError(where, "a face refers to a normal that does not exist");
                if (ix.texcoord_index >= 0 && std::size_t(ix.texcoord_index) >= uvCount)
                    throw InputError(where, "a face refers to a texture coordinate that does not exist");
                const CornerKey key{
                    (std::uint64_t(std::uint32_t(ix.vertex_index)) << 32) | std::uint32_t(ix.normal_index + 1),
                    std::uint32_t(ix.texcoord_index + 1)};
                auto [v, fresh] = b.vertexOf.try_emplace(key, static_cast<std::uint32_t>(g.positions.size()));
                if (fresh) {
                    const float* p = &attrib.vertices[3 * std::size_t(ix.vertex_index)];
                    g.positions.emplace_back(p[0], p[1], p[2]);
                    if (colored) {
                        const float* c = &attrib.colors[3 * std::size_t(ix.vertex_index)];
                        g.colors.emplace_back(glm::clamp(vec3(c[0], c[1], c[2]), vec3(0.f), vec3(1.f)), 1.f);
                    }
                    if (ix.normal_index >= 0) {
                        const float* nn = &attrib.normals[3 * std::size_t(ix.normal_index)];
                        g.normals.emplace_back(nn[0], nn[1], nn[2]);
                    } else {
                        g.normals.emplace_back(0.f);
                        b.allNormals = false;
                    }
                    if (ix.texcoord_index >= 0) {
                        const float* t = &attrib.texcoords[2 * std::size_t(ix.texcoord_index)];
                        g.uv0.emplace_back(t[0], 1.f - t[1]);  // OBJ's v runs up, rtlab's (glTF's) down
                    } else {
                        g.uv0.emplace_back(0.f);
                        b.allUvs = false;
                    }
                }
                polygon.push_back(g.positions[v->second]);
                polygonVertices.push_back(v->second);
            }
            corner += n;
            triangles.clear();
            triangulate(polygon, triangles);
            for (const std::uint32_t t : triangles) g.indices.push_back(polygonVertices[t]);
        }
        if (corner != mesh.indices.size())  // the face counts and the corners disagree
            throw InputError(where, asset.name + ": its faces have " + std::to_string(corner) +
                                        " corners, the parser read " + std::to_string(mesh.indices.size()));
        for (std::size_t i = 0; i < asset.geometries.size(); ++i) {
            Geometry& g = asset.geometries[i];
            bool usable = builds[i].allNormals;
            for (vec3& nrm : g.normals) {
                const float len = glm::length(nrm);
                if (!(len > 0.f) || !std::isfinite(len)) usable = false;
                else nrm /= len;
            }
            if (!usable) g.normals = generateVertexNormals(g.positions, g.indices);
            if (!builds[i].allUvs) g.uv0.clear();
        }
        meshes.push_back(std::move(asset));
    }
    if (skippedLines || skippedPoints)
        warnings.push_back(where + ": skipped " + std::to_string(skippedLines) + " line(s) and " +
                           std::to_string(skippedPoints) + " point(s) (rtlab traces triangles)");
    std::size_t triangleCount = 0;
    for (const MeshAsset& m : meshes) triangleCount += m.triangleCount();
    if (triangleCount == 0) {
        // As glTF: a file of points or lines renders as an empty scene with a warning; a file of nothing is an error.
        if (vertexCount == 0) throw InputError(where, "no geometry (no vertex, no face)");
        warnings.push_back(where + ": no faces (" + std::to_string(vertexCount) + " vertices, " +
                           std::to_string(skippedLines) + " line(s), " + std::to_string(skippedPoints) +
                           " point(s)): an empty scene, rtlab traces triangles");
    }

    // Step: commit (nothing below can fail on bad input).
    const std::vector<MaterialId> materialIds =
        commitMaterials(world, std::move(textures), std::move(materials), skippedLines, skippedPoints, warnings);
    std::vector<Entity> entities;
    const bool parentAlive = world.alive(parent);
    for (MeshAsset& mesh : meshes) {
        for (Geometry& g : mesh.geometries) g.material = materialIds[g.material];
        const std::string name = mesh.name;
        const MeshId id = world.addMesh(std::move(mesh));
        const Entity e = world.create(name);
        world.emplace(e, LocalTransform{});
        if (parentAlive) world.emplace(e, Parent{parent});
        world.emplace(e, MeshInstance{id});
        entities.push_back(e);
    }
    return entities;
}

}  // namespace rtlab::ecs::load
