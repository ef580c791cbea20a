// PLY and FBX scenes through assimp 5.2 (docs/scene-format.md, "PLY and FBX"):
// the importer's node hierarchy as entities with their transforms, each
// mesh's triangles (assimp triangulates; points and lines are skipped with a
// warning), normals (computed where missing), UV0 and materials (diffuse
// colour and texture, opacity, shininess, emission, refraction index).
// Anything the importer rejects is an InputError naming the file.
#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include "reader_check.hpp"

#include <assimp/Importer.hpp>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <assimp/version.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <iostream>
#include <cctype>
#include <fstream>
#include <sstream>
#include <cmath>
#include <functional>
#include <map>
#include <optional>

namespace rtlab::ecs::load {
namespace {

mat4 toMat4(const aiMatrix4x4& m) {
    // assimp is row-major with column vectors (a1..a4 the first row); glm is column-major.
    return mat4(m.a1, m.b1, m.c1, m.d1, m.a2, m.b2, m.c2, m.d2, m.a3, m.b3, m.c3, m.d3, m.a4, m.b4, m.c4, m.d4);
}

// A material's diffuse texture: embedded in the file (compressed) or a file beside it.
std::optional<Texture> textureOf(const aiScene* scene, const aiMaterial* material, const std::filesystem::path& dir,
                                 std::vector<std::string>& warnings, const std::string& where, DecodeBudget& budget) {
    aiString name;
    if (material->GetTexture(aiTextureType_DIFFUSE, 0, &name) != AI_SUCCESS) return std::nullopt;
    std::optional<Texture> t;
    if (const aiTexture* embedded = scene->GetEmbeddedTexture(name.C_Str())) {
        if (embedded->mHeight == 0)  // compressed (png, jpg, ...): mWidth bytes
            t = decodeTexture(reinterpret_cast<const unsigned char*>(embedded->pcData), embedded->mWidth,
                              std::string("embedded ") + name.C_Str(), budget);
    } else {
        t = readTextureNamed(dir, name.C_Str(), budget);
    }
    if (!t) warnings.push_back(where + ": texture " + name.C_Str() + " not found or not readable, left out");
    return t;
}

// A PLY header's element counts against the file's size, before assimp
// reserves memory for them (a 1 KB file declaring 2e8 vertices made it touch
// 2.4 GB): each element needs at least its scalar properties' bytes (binary)
// or two characters per property (ascii: a digit and a separator), a list at
// least its count, within a small slack. InputError naming the element
// otherwise, and for a header that does not start with "ply" or does not end
// (a file cut inside its header made assimp 5.2 loop forever); an empty file
// is left to assimp's own message.
void checkPlyCounts(const std::filesystem::path& path, const std::string& where) {
    // Step: the header from the first 1 MiB, lines ended by \n, \r\n or \r.
    constexpr std::size_t kHeaderLimit = 1u << 20;
    std::ifstream in(path, std::ios::binary);
    std::string head(kHeaderLimit, '\0');
    in.read(head.data(), static_cast<std::streamsize>(head.size()));
    head.resize(static_cast<std::size_t>(in.gcount()));
    std::size_t headerBytes = 0, lines = 0;
    bool binary = false, ended = false;
    struct Element {
        std::string name;
        std::uint64_t count = 0, minBytes = 0;
    };
    std::vector<Element> elements;
    const auto scalarBytes = [](const std::string& type) -> std::uint64_t {
        if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
        if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
        if (type == "double" || type == "float64") return 8;
        return 4;  // int, uint, float and their sized names
    };
    while (headerBytes < head.size()) {
        std::size_t end = head.find_first_of("\r\n", headerBytes);
        if (end == std::string::npos) break;
        const std::string line = head.substr(headerBytes, end - headerBytes);
        headerBytes = end + (head.compare(end, 2, "\r\n") == 0 ? 2 : 1);
        std::istringstream words(line);
        std::string keyword;
        words >> keyword;
        if (lines++ == 0) {  // "ply", as assimp reads it: any case, surrounding blanks
            std::string magic = keyword;
            std::transform(magic.begin(), magic.end(), magic.begin(), [](unsigned char c) { return std::tolower(c); });
            if (magic != "ply") throw InputError(where, "not a PLY file (its first line is not 'ply')");
            continue;
        }
        if (keyword == "format") {
            std::string format;
            words >> format;
            binary = format.rfind("binary", 0) == 0;
        } else if (keyword == "element") {
            Element e;
            std::string count;
            words >> e.name >> count;
            if (count.empty() || count.size() > 19 || count.find_first_not_of("0123456789") != std::string::npos)
                throw InputError(where, "PLY element '" + e.name + "' has count '" + count + "', not a whole number");
            e.count = std::stoull(count);
            elements.push_back(e);
        } else if (keyword == "property" && !elements.empty()) {
            std::string type, countType;
            words >> type;
            if (type == "list") words >> countType;
            elements.back().minBytes += binary ? scalarBytes(type == "list" ? countType : type) : 2;
        } else if (keyword == "end_header") {
            ended = true;
            break;
        }
    }
    if (head.empty()) return;  // empty: assimp says so
    if (!ended) throw InputError(where, "PLY header has no end_header line in its first MiB (truncated or not PLY)");
    std::error_code ec;
    const std::uint64_t fileBytes = std::filesystem::file_size(path, ec);
    if (ec) return;
    // (+1: an ascii file's last value may lack its separator.)
    const std::uint64_t bodyBytes = (fileBytes > headerBytes ? fileBytes - headerBytes : 0) + (binary ? 0 : 1);
    long double needed = 0.0L;
    // Slack of 1% + 4 KB: a file that ends a few elements early (assimp-testmodels'
    // pond.0.ply lacks 69 bytes) is assimp's to read; the allocation stays bounded.
    const long double limit = static_cast<long double>(bodyBytes) * 1.01L + 4096.0L;
    for (const Element& e : elements) {
        needed += static_cast<long double>(e.count) * static_cast<long double>(e.minBytes);
        if (needed > limit)
            throw InputError(where, "PLY header declares " + std::to_string(e.count) + " '" + e.name +
                                        "' elements, more than the " + std::to_string(bodyBytes) +
                                        " bytes after the header can hold (truncated or corrupt)");
    }
}

// Reads `path` with assimp: without post-processing first, every face's
// indices checked, then triangulated and its vertices joined. assimp's own
// steps trust the indices: a binary PLY cut inside its faces crashed
// Triangulate / JoinIdenticalVertices (assimp 5.2). (No
// aiProcess_ValidateDataStructure: it rejects point clouds, meshes without
// faces; points and lines are skipped by the loader, face by face.)
const aiScene* importChecked(Assimp::Importer& importer, const std::filesystem::path& path, const std::string& where) {
    const auto failed = [&] {
        std::string error = importer.GetErrorString();
        if (error.empty()) error = "not a readable scene";
        return InputError(where, error.substr(0, error.find('\n')));
    };
    const aiScene* raw = importer.ReadFile(path.string(), 0);
    if (!raw || (raw->mFlags & AI_SCENE_FLAGS_INCOMPLETE) || !raw->mRootNode) throw failed();
    for (unsigned i = 0; i < raw->mNumMeshes; ++i) {
        const aiMesh* am = raw->mMeshes[i];
        if (!am || (am->mNumVertices > 0 && !am->mVertices) || (am->mNumFaces > 0 && !am->mFaces))
            throw InputError(where, "mesh " + std::to_string(i) + ": missing vertex or face data");
        for (unsigned f = 0; f < am->mNumFaces; ++f) {
            const aiFace& face = am->mFaces[f];
            if (face.mNumIndices == 0 || !face.mIndices)
                throw InputError(where, "mesh " + std::to_string(i) + ": face " + std::to_string(f) + " has no corner");
            for (unsigned k = 0; k < face.mNumIndices; ++k)
                if (face.mIndices[k] >= am->mNumVertices)
                    throw InputError(where, "mesh " + std::to_string(i) + ": face " + std::to_string(f) +
                                                " refers to vertex " + std::to_string(face.mIndices[k]) + " of " +
                                                std::to_string(am->mNumVertices) + " (truncated or corrupt)");
        }
    }
    const aiScene* scene = importer.ApplyPostProcessing(aiProcess_Triangulate | aiProcess_JoinIdenticalVertices);
    if (!scene || !scene->mRootNode) throw failed();
    return scene;
}

}  // namespace

void readWithAssimpForCheck(const std::filesystem::path& path) {
    Assimp::Importer importer;
    importChecked(importer, path, path.string());
}

std::vector<Entity> loadWithAssimp(World& world, const std::filesystem::path& path, Entity parent) {
    const std::string where = path.string();
    std::string extension = path.extension().string();
    std::transform(extension.begin(), extension.end(), extension.begin(),
                   [](unsigned char c) { return std::tolower(c); });
    if (extension == ".ply") checkPlyCounts(path, where);
    checkInSeparateProcess("assimp", "assimp", path, "", where);
    Assimp::Importer importer;
    const aiScene* scene = importChecked(importer, path, where);
    std::vector<std::string> warnings;

    // Step: materials and their textures.
    std::vector<Texture> textures;
    std::vector<Material> materials;
    DecodeBudget budget;
    std::map<std::string, std::optional<TextureId>> textureNamed;  // each texture decoded once
    for (unsigned i = 0; i < scene->mNumMaterials; ++i) {
        const aiMaterial* am = scene->mMaterials[i];
        Material m;
        aiString name;
        if (am->Get(AI_MATKEY_NAME, name) == AI_SUCCESS) m.name = name.C_Str();
        aiColor3D c;
        if (am->Get(AI_MATKEY_COLOR_DIFFUSE, c) == AI_SUCCESS) m.baseColor = vec4(c.r, c.g, c.b, 1.f);
        if (am->Get(AI_MATKEY_COLOR_EMISSIVE, c) == AI_SUCCESS) m.emissive = vec3(c.r, c.g, c.b);
        float v = 0.f;
        if (am->Get(AI_MATKEY_OPACITY, v) == AI_SUCCESS && std::isfinite(v) && v < 1.f) {
            m.baseColor.a = std::clamp(v, 0.f, 1.f);
            m.alphaMode = AlphaMode::Blend;
        }
        if (am->Get(AI_MATKEY_SHININESS, v) == AI_SUCCESS && std::isfinite(v) && v > 0.f)
            m.roughness = roughnessFromPhongExponent(v);
        if (am->Get(AI_MATKEY_REFRACTI, v) == AI_SUCCESS && std::isfinite(v) && v > 0.f) m.ior = v;
        aiString textureName;
        if (am->GetTexture(aiTextureType_DIFFUSE, 0, &textureName) == AI_SUCCESS) {
            const auto [it, added] = textureNamed.try_emplace(textureName.C_Str());
            if (added) {
                std::optional<Texture> t;
                try {
                    t = textureOf(scene, am, path.parent_path(), warnings, where, budget);
                } catch (const InputError& e) {
                    throw InputError(where, e.what());  // the texture's problem, named within the file
                }
                if (t) {
                    it->second = static_cast<TextureId>(textures.size());
                    textures.push_back(std::move(*t));
                }
            }
            if (it->second) m.baseColorTexture = *it->second;
        }
        for (int k = 0; k < 3; ++k)
            if (!std::isfinite(m.baseColor[k])) m.baseColor[k] = 1.f;
        materials.push_back(std::move(m));
    }
    const MaterialId defaultMaterial = static_cast<MaterialId>(materials.size());
    materials.push_back(Material{"default"});

    // Step: meshes (triangles only).
    std::vector<std::optional<MeshAsset>> meshes(scene->mNumMeshes);
    std::uint32_t skippedPoints = 0, skippedLines = 0;
    for (unsigned i = 0; i < scene->mNumMeshes; ++i) {
        const aiMesh* am = scene->mMeshes[i];
        if (am->mNumFaces == 0) {  // a point cloud (PLY without faces)
            skippedPoints += am->mNumVertices;
            continue;
        }
        if (!(am->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) {
            if (am->mPrimitiveTypes & aiPrimitiveType_POINT) skippedPoints += am->mNumFaces;
            else skippedLines += am->mNumFaces;
            continue;
        }
        if (!am->mVertices || !am->mFaces) throw InputError(where, "mesh " + std::to_string(i) + " has no vertex data");
        Geometry g;
        g.positions.reserve(am->mNumVertices);
        for (unsigned v = 0; v < am->mNumVertices; ++v) {
            const aiVector3D& p = am->mVertices[v];
            if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
                throw InputError(where, "mesh " + std::to_string(i) + ": a vertex coordinate is not a finite number");
            g.positions.emplace_back(p.x, p.y, p.z);
        }
        for (unsigned f = 0; f < am->mNumFaces; ++f) {
            const aiFace& face = am->mFaces[f];
            if (face.mNumIndices != 3) {  // a point or line of a mixed mesh
                (face.mNumIndices == 1 ? skippedPoints : skippedLines) += 1;
                continue;
            }
            for (unsigned k = 0; k < 3; ++k) {
                if (face.mIndices[k] >= am->mNumVertices)
                    throw InputError(where, "mesh " + std::to_string(i) + ": a face index out of range");
                g.indices.push_back(face.mIndices[k]);
            }
        }
        if (g.indices.empty()) continue;
        bool normalsUsable = am->HasNormals();
        if (normalsUsable) {
            for (unsigned v = 0; v < am->mNumVertices; ++v) {
                vec3 n(am->mNormals[v].x, am->mNormals[v].y, am->mNormals[v].z);
                const float len = glm::length(n);
                if (!(len > 0.f) || !std::isfinite(len)) normalsUsable = false;
                g.normals.push_back(normalsUsable ? n / len : vec3(0.f));
            }
        }
        if (!normalsUsable) g.normals = generateVertexNormals(g.positions, g.indices);
        if (am->HasTextureCoords(0))
            for (unsigned v = 0; v < am->mNumVertices; ++v)
                g.uv0.emplace_back(am->mTextureCoords[0][v].x, 1.f - am->mTextureCoords[0][v].y);
        if (am->HasVertexColors(0))  // PLY red/green/blue[/alpha], FBX LayerElementColor: clamped to [0, 1]
            for (unsigned v = 0; v < am->mNumVertices; ++v) {
                const aiColor4D& c = am->mColors[0][v];
                const vec4 color(c.r, c.g, c.b, c.a);
                const bool finite =
                    std::isfinite(c.r) && std::isfinite(c.g) && std::isfinite(c.b) && std::isfinite(c.a);
                g.colors.push_back(finite ? glm::clamp(color, vec4(0.f), vec4(1.f)) : vec4(1.f));
            }
        g.material = am->mMaterialIndex < scene->mNumMaterials ? MaterialId(am->mMaterialIndex) : defaultMaterial;
        MeshAsset asset;
        asset.name = am->mName.length ? am->mName.C_Str() : "mesh " + std::to_string(i);
        asset.geometries.push_back(std::move(g));
        meshes[i] = std::move(asset);
    }
    std::size_t triangles = 0;
    for (const auto& m : meshes)
        if (m) triangles += m->triangleCount();
    if (triangles == 0 && skippedLines == 0 && skippedPoints == 0)
        throw InputError(where, "no geometry (no triangle, line or point)");
    if (skippedLines || skippedPoints)
        warnings.push_back(where + ": skipped " + std::to_string(skippedLines) + " line(s) and " +
                           std::to_string(skippedPoints) + " point(s) (rtlab traces triangles)");

    // Step: commit; the node tree as entities (nothing below can fail on bad input).
    const std::vector<MaterialId> materialIds =
        commitMaterials(world, std::move(textures), std::move(materials), skippedLines, skippedPoints, warnings);
    std::vector<MeshId> meshIds(meshes.size(), ~MeshId(0));
    for (std::size_t i = 0; i < meshes.size(); ++i) {
        if (!meshes[i]) continue;
        for (Geometry& g : meshes[i]->geometries) g.material = materialIds[g.material];
        meshIds[i] = world.addMesh(std::move(*meshes[i]));
    }
    // Step: the file's cameras, by the node that carries each (as assimp names
    // them); non-finite ones are left out. Lights are not read: assimp folds an
    // FBX light's intensity (a percentage, no physical unit) into its colour, so
    // a file's lamp would light the scene arbitrarily; the default sun does.
    std::map<std::string, const aiCamera*> cameraOf;
    for (unsigned i = 0; i < scene->mNumCameras; ++i)
        cameraOf.emplace(scene->mCameras[i]->mName.C_Str(), scene->mCameras[i]);
    const auto finite3 = [](const aiVector3D& v) {
        return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
    };
    const auto toVec3 = [](const aiVector3D& v) { return vec3(v.x, v.y, v.z); };
    // A child of `node`'s entity at `position`, looking along `along` (its -Z).
    const auto placed = [&](Entity node, const std::string& name, const aiVector3D& position, const aiVector3D& along,
                            const aiVector3D& up) {
        const Entity child = world.create(name);
        vec3 u = toVec3(up);
        if (!(glm::length(glm::cross(toVec3(along), u)) > 0.f))
            u = std::abs(along.y) < 0.9f ? vec3(0, 1, 0) : vec3(1, 0, 0);
        world.emplace(child, LocalTransform{toVec3(position),
                                            orientationLookingAlong(glm::normalize(toVec3(along)), glm::normalize(u)),
                                            vec3(1.f)});
        world.emplace(child, Parent{node});
        return child;
    };
    std::vector<Entity> cameras;
    const auto addCamera = [&](Entity node, const aiCamera& c) {
        const float aspect = c.mAspect > 0.f && std::isfinite(c.mAspect) ? c.mAspect : 16.f / 9.f;
        // assimp before 5.3 stores the whole horizontal angle (5.3 halved it:
        // assimp PR #5175); spider.fbx's Blender camera: 49.1 degrees, whole.
        const bool wholeAngle = aiGetVersionMajor() * 100 + aiGetVersionMinor() < 503;
        const float halfAngle = wholeAngle ? 0.5f * c.mHorizontalFOV : c.mHorizontalFOV;
        const float yfov = 2.f * std::atan(std::tan(halfAngle) / aspect);
        if (!finite3(c.mPosition) || !finite3(c.mLookAt) || !finite3(c.mUp) ||
            !(glm::length(toVec3(c.mLookAt)) > 0.f) || !(yfov > 1e-3f && yfov < 3.1f)) {
            world.loadReport().warnings.push_back(where + ": camera " + c.mName.C_Str() +
                                                  " left out (degenerate or non-finite)");
            return;
        }
        const float znear = c.mClipPlaneNear > 0.f && std::isfinite(c.mClipPlaneNear) ? c.mClipPlaneNear : 0.01f;
        const float zfar = c.mClipPlaneFar > znear && std::isfinite(c.mClipPlaneFar) ? c.mClipPlaneFar : 1e4f * znear;
        const Entity camera = placed(node, std::string("camera ") + c.mName.C_Str(), c.mPosition, c.mLookAt, c.mUp);
        world.emplace(camera, Camera{yfov, znear, zfar, 0.f});
        cameras.push_back(camera);
    };
    std::vector<Entity> roots;
    const std::function<void(const aiNode*, Entity, int)> visit = [&](const aiNode* node, Entity up, int depth) {
        if (depth > 1000) return;  // a deeper tree than any real file: its rest is left out
        const Entity e = world.create(node->mName.C_Str());
        world.emplace(e, localTransformOf(toMat4(node->mTransformation)));
        if (world.alive(up)) world.emplace(e, Parent{up});
        else roots.push_back(e);
        if (const auto c = cameraOf.find(node->mName.C_Str()); c != cameraOf.end()) addCamera(e, *c->second);
        for (unsigned k = 0; k < node->mNumMeshes; ++k) {
            const unsigned mesh = node->mMeshes[k];
            if (mesh >= meshIds.size() || meshIds[mesh] == ~MeshId(0)) continue;
            const Entity child = node->mNumMeshes == 1 ? e : world.create(node->mName.C_Str());
            if (child != e) world.emplace(child, LocalTransform{}), world.emplace(child, Parent{e});
            world.emplace(child, MeshInstance{meshIds[mesh]});
        }
        for (unsigned k = 0; k < node->mNumChildren; ++k) visit(node->mChildren[k], e, depth + 1);
    };
    visit(scene->mRootNode, parent, 0);
    // Step: clip planes are in the camera node's units; the node tree may scale
    // them (Blender's FBX: centimetres, a node scale of 100), rays run in the world's.
    for (const Entity e : cameras) {
        const float scale = glm::length(vec3(world.computeInstanceWorldFromObject(e)[0]));
        if (std::isfinite(scale) && scale > 0.f)
            world.patch<Camera>(e, [&](Camera& c) { c.znear *= scale, c.zfar *= scale; });
    }
    return roots;
}

}  // namespace rtlab::ecs::load
