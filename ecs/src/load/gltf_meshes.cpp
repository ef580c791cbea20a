// Stage 3 of the glTF loader, meshes: glTF meshes and their primitives converted into MeshAssets (modes,
// skin attributes, index lists, normals, morph targets) and the per-instance variants (rigid or deformable).
#include "gltf_internal.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace rtlab::ecs::load::gltf {

void GltfConverter::stageInstance(int nodeIndex, StagedNode& out) {
    const tg::Node& node = m_.nodes[static_cast<std::size_t>(nodeIndex)];
    BaseMesh& base = baseMesh(node.mesh);
    if (base.asset.geometries.empty()) return;  // points/lines only: nothing to trace
    const bool skinned = node.skin >= 0;
    if (skinned) {
        if (!base.skinnable)
            fail_(cat(nodeLabel(nodeIndex), " has a skin but ", meshLabel(node.mesh),
                      " lacks JOINTS_0/WEIGHTS_0 in some primitive"));
        const StagedSkin& skin = stageSkin(node.skin);
        if (base.jointsNeeded > skin.jointNodes.size())
            fail_(cat(meshLabel(node.mesh), " uses joint index ", base.jointsNeeded - 1, " but skin ", node.skin,
                      " of ", nodeLabel(nodeIndex), " has ", skin.jointNodes.size(), " joints"));
        out.skin = node.skin;
    }
    if (base.targetCount > 0) {
        std::vector<float> weights(base.targetCount, 0.f);
        const std::vector<double>* source = !node.weights.empty() ? &node.weights
                                            : !m_.meshes[static_cast<std::size_t>(node.mesh)].weights.empty()
                                                ? &m_.meshes[static_cast<std::size_t>(node.mesh)].weights
                                                : nullptr;
        if (source) {
            if (source->size() != base.targetCount)
                fail_(cat(nodeLabel(nodeIndex), ": ", source->size(), " morph weights for ", base.targetCount,
                          " morph targets of ", meshLabel(node.mesh)));
            for (std::size_t i = 0; i < weights.size(); ++i) {
                if (!std::isfinite((*source)[i])) fail_(cat(nodeLabel(nodeIndex), ": non-finite morph weight"));
                weights[i] = static_cast<float>((*source)[i]);
            }
        }
        out.morph = MorphWeights{std::move(weights)};
    } else if (!node.weights.empty()) {
        fail_(cat(nodeLabel(nodeIndex), " has morph weights but ", meshLabel(node.mesh), " has no morph targets"));
    }

    const bool deformable = skinned || base.targetCount > 0;
    if (!deformable) {
        if (base.rigidVariant < 0) {
            MeshAsset rigid = base.asset;
            for (Geometry& g : rigid.geometries) {
                g.joints.clear();
                g.weights.clear();
            }
            base.rigidVariant = static_cast<int>(s_.meshes.size());
            s_.meshes.push_back(std::move(rigid));
        }
        out.mesh = base.rigidVariant;
        return;
    }
    // Deformation writes into the asset: every deformable instance owns one
    // (with rest positions and normals: charged as twice its vertices).
    std::uint64_t copyBytes = 0;
    for (const Geometry& g : base.asset.geometries) {
        copyBytes += 2 * (g.positions.size() + g.normals.size()) * sizeof(vec3) + g.uv0.size() * sizeof(vec2) +
                     g.colors.size() * sizeof(vec4) + g.indices.size() * sizeof(std::uint32_t) +
                     g.joints.size() * sizeof(glm::uvec4) + g.weights.size() * sizeof(vec4);
        for (const MorphTarget& t : g.morphTargets)
            copyBytes += (t.positionDeltas.size() + t.normalDeltas.size()) * sizeof(vec3);
    }
    chargeDecoded(copyBytes, nodeLabel(nodeIndex));
    MeshAsset copy = base.asset;
    for (Geometry& g : copy.geometries) {
        if (!skinned) {
            g.joints.clear();
            g.weights.clear();
        }
        g.restPositions = g.positions;
        g.restNormals = g.normals;
    }
    out.mesh = static_cast<int>(s_.meshes.size());
    s_.meshes.push_back(std::move(copy));
}

// The geometry the loaded scene declares it will decode, against the budget
// before anything is read: each reached mesh's primitives' accessors once
// (a mesh is converted once), and for each reached node that deforms its
// mesh (skinned or morphed: the instance owns a copy) the mesh again plus its
// positions and normals (the rest pose). view() and stageInstance() then
// charge what is actually read and copied. Stops at the limit, so the sums
// (each term below 2^38) never wrap.
void GltfConverter::checkDeclaredGeometry(const std::vector<int>& roots) const {
    const std::uint64_t limit = budget_.geometryLimit();
    std::uint64_t total = budget_.geometryBytes;
    const auto add = [&](std::uint64_t& sum, std::uint64_t bytes) {
        sum += bytes;
        if (sum > limit)
            fail_(cat("the scene's meshes and deformable instances declare more than ", limit,
                      " bytes of geometry, the most it may decode (1 GiB + 64 x its glTF buffers' bytes)"));
    };
    const auto declaredBytes = [&](int accessor) -> std::uint64_t {
        if (accessor < 0 || static_cast<std::size_t>(accessor) >= m_.accessors.size()) return 0;
        const tg::Accessor& acc = m_.accessors[static_cast<std::size_t>(accessor)];
        return std::uint64_t(acc.count) * std::uint64_t(componentCount(acc.type)) * 4u;
    };
    // Step: the nodes the scene reaches (the hierarchy is validated: a forest).
    std::vector<int> reached, stack(roots.begin(), roots.end());
    while (!stack.empty()) {
        const int n = stack.back();
        stack.pop_back();
        if (n < 0 || static_cast<std::size_t>(n) >= m_.nodes.size()) continue;
        reached.push_back(n);
        for (const int c : m_.nodes[static_cast<std::size_t>(n)].children) stack.push_back(c);
    }
    // Step: their meshes once each, then the deformable copies.
    constexpr std::uint64_t kNotCounted = ~std::uint64_t(0);
    std::vector<std::uint64_t> meshBytes(m_.meshes.size(), kNotCounted), restBytes(m_.meshes.size(), 0);
    for (const int n : reached) {
        const int mi = m_.nodes[static_cast<std::size_t>(n)].mesh;
        if (mi < 0 || static_cast<std::size_t>(mi) >= m_.meshes.size()) continue;
        const auto i = static_cast<std::size_t>(mi);
        if (meshBytes[i] != kNotCounted) continue;
        meshBytes[i] = 0;
        for (const tg::Primitive& prim : m_.meshes[i].primitives) {
            for (const auto& [name, accessor] : prim.attributes) add(meshBytes[i], declaredBytes(accessor));
            add(meshBytes[i], declaredBytes(prim.indices));
            for (const std::map<std::string, int>& target : prim.targets)
                for (const auto& [name, accessor] : target) add(meshBytes[i], declaredBytes(accessor));
            add(restBytes[i], declaredBytes(attribute(prim, "POSITION")) + declaredBytes(attribute(prim, "NORMAL")));
        }
        add(total, meshBytes[i]);
    }
    for (const int n : reached) {
        const tg::Node& node = m_.nodes[static_cast<std::size_t>(n)];
        if (node.mesh < 0 || static_cast<std::size_t>(node.mesh) >= m_.meshes.size()) continue;
        const auto i = static_cast<std::size_t>(node.mesh);
        const bool morphed = !m_.meshes[i].primitives.empty() && !m_.meshes[i].primitives.front().targets.empty();
        if (node.skin >= 0 || morphed) add(total, meshBytes[i] + restBytes[i]);
    }
}

BaseMesh& GltfConverter::baseMesh(int meshIndex) {
    auto& slot = baseMeshes_[static_cast<std::size_t>(meshIndex)];
    if (!slot) slot = convertMesh(meshIndex);
    return *slot;
}

BaseMesh GltfConverter::convertMesh(int meshIndex) {
    const tg::Mesh& mesh = m_.meshes[static_cast<std::size_t>(meshIndex)];
    const std::string label = meshLabel(meshIndex);
    if (mesh.primitives.empty()) fail_(cat(label, " has no primitives"));
    BaseMesh out;
    out.asset.name = mesh.name.empty() ? cat("mesh ", meshIndex) : mesh.name;
    out.targetCount = mesh.primitives.front().targets.size();
    out.skinnable = true;
    for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
        const tg::Primitive& prim = mesh.primitives[p];
        const std::string where = cat(label, " primitive ", p);
        if (prim.targets.size() != out.targetCount)
            fail_(cat(where, " has ", prim.targets.size(), " morph targets, primitive 0 has ", out.targetCount));
        const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
        if (mode > TINYGLTF_MODE_TRIANGLE_FAN) fail_(cat(where, ": invalid primitive mode ", mode));
        if (mode < TINYGLTF_MODE_TRIANGLES) {
            // Points and lines: validated like triangles, then left out
            // (a ray tracer renders triangles); counted for the warning.
            const int pos = attribute(prim, "POSITION");
            if (pos < 0) fail_(cat(where, " has no POSITION attribute"));
            const std::size_t n = readPositions(pos, cat("POSITION of ", where)).size();
            if (prim.indices >= 0) readIndices(prim.indices, cat("indices of ", where), n);
            ++(mode == TINYGLTF_MODE_POINTS ? s_.skippedPointPrimitives : s_.skippedLinePrimitives);
            continue;
        }
        bool hasSkinAttributes = false;
        out.asset.geometries.push_back(convertPrimitive(prim, where, hasSkinAttributes, out.jointsNeeded));
        out.skinnable = out.skinnable && hasSkinAttributes;
    }
    if (!mesh.weights.empty() && mesh.weights.size() != out.targetCount)
        fail_(cat(label, " has ", mesh.weights.size(), " default weights for ", out.targetCount, " morph targets"));
    return out;
}

Geometry GltfConverter::convertPrimitive(const tg::Primitive& prim, const std::string& where, bool& hasSkinAttributes,
                                         std::uint32_t& jointsNeeded) {
    Geometry g;
    const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
    std::optional<std::vector<std::uint32_t>> dracoIndices = decodeDraco(prim, where);

    const int posAccessor = attribute(prim, "POSITION");
    if (posAccessor < 0) fail_(cat(where, " has no POSITION attribute"));
    g.positions = readPositions(posAccessor, cat("POSITION of ", where));
    const std::size_t n = g.positions.size();

    const int normalAccessor = attribute(prim, "NORMAL");
    if (normalAccessor >= 0) g.normals = readNormals(normalAccessor, cat("NORMAL of ", where), n);

    if (const int uvAccessor = attribute(prim, "TEXCOORD_0"); uvAccessor >= 0) {
        const std::string what = cat("TEXCOORD_0 of ", where);
        const AccessorView v =
            quantized_ ? view(uvAccessor, what, {TINYGLTF_TYPE_VEC2},
                              {{kFloat},
                               {kByte, false, true},
                               {kUByte, false, true},
                               {kShort, false, true},
                               {kUShort, false, true}},
                              "VEC2 float or (KHR_mesh_quantization) byte/short")
                       : view(uvAccessor, what, {TINYGLTF_TYPE_VEC2}, {{kFloat}, {kUByte, true}, {kUShort, true}},
                              "VEC2 float or normalized unsigned byte/short");
        requireCount(v, what, n);
        const std::vector<float> f = readFloats(v, what);
        g.uv0.resize(n);
        for (std::size_t i = 0; i < n; ++i) g.uv0[i] = vec2(f[2 * i], f[2 * i + 1]);
    }

    // COLOR_0 (linear RGB or RGBA multiplying the base colour), clamped to [0, 1].
    if (const int colorAccessor = attribute(prim, "COLOR_0"); colorAccessor >= 0) {
        const std::string what = cat("COLOR_0 of ", where);
        const AccessorView v =
            view(colorAccessor, what, {TINYGLTF_TYPE_VEC3, TINYGLTF_TYPE_VEC4},
                 {{kFloat}, {kUByte, true}, {kUShort, true}}, "VEC3/VEC4 float or normalized unsigned byte/short");
        requireCount(v, what, n);
        const std::vector<float> f = readFloats(v, what);
        const std::size_t k = f.size() / std::max<std::size_t>(n, 1);
        g.colors.resize(n);
        for (std::size_t i = 0; i < n; ++i) {
            const vec4 c(f[k * i], f[k * i + 1], f[k * i + 2], k == 4 ? f[k * i + 3] : 1.f);
            g.colors[i] = glm::clamp(c, vec4(0.f), vec4(1.f));
            if (!std::isfinite(c.r) || !std::isfinite(c.g) || !std::isfinite(c.b) || !std::isfinite(c.a))
                fail_(cat(what, " has a non-finite value"));
        }
    }

    const int jointsAccessor = attribute(prim, "JOINTS_0");
    const int weightsAccessor = attribute(prim, "WEIGHTS_0");
    if ((jointsAccessor >= 0) != (weightsAccessor >= 0)) fail_(cat(where, " has only one of JOINTS_0 and WEIGHTS_0"));
    hasSkinAttributes = jointsAccessor >= 0;
    if (hasSkinAttributes) {
        const std::string jWhat = cat("JOINTS_0 of ", where), wWhat = cat("WEIGHTS_0 of ", where);
        const AccessorView jv = view(jointsAccessor, jWhat, {TINYGLTF_TYPE_VEC4},
                                     {{kUByte, false, true}, {kUShort, false, true}}, "VEC4 unsigned byte/short");
        requireCount(jv, jWhat, n);
        const AccessorView wv =
            view(weightsAccessor, wWhat, {TINYGLTF_TYPE_VEC4}, {{kFloat}, {kUByte, true}, {kUShort, true}},
                 "VEC4 float or normalized unsigned byte/short");
        requireCount(wv, wWhat, n);
        const std::vector<std::uint32_t> j = readUInts(jv);
        const std::vector<float> w = readFloats(wv, wWhat);
        g.joints.resize(n);
        g.weights.resize(n);
        for (std::size_t i = 0; i < n; ++i) {
            vec4 wi(w[4 * i], w[4 * i + 1], w[4 * i + 2], w[4 * i + 3]);
            const glm::uvec4 ji(j[4 * i], j[4 * i + 1], j[4 * i + 2], j[4 * i + 3]);
            if (wi.x < 0.f || wi.y < 0.f || wi.z < 0.f || wi.w < 0.f)
                fail_(cat("accessor ", wv.index, " (", wWhat, ") has a negative weight at vertex ", i));
            const float sum = wi.x + wi.y + wi.z + wi.w;
            if (!(sum > 0.f) || !std::isfinite(sum)) wi = vec4(1.f, 0.f, 0.f, 0.f);
            else wi /= sum;
            for (int k = 0; k < 4; ++k)
                if (wi[k] > 0.f) jointsNeeded = std::max(jointsNeeded, ji[k] + 1u);
            g.joints[i] = ji;
            g.weights[i] = wi;
        }
    }

    // Indices: validated against the vertex count, then converted to a list.
    std::vector<std::uint32_t> source;
    if (dracoIndices) {
        source = std::move(*dracoIndices);  // checked against the decoded point count
    } else if (prim.indices >= 0) {
        source = readIndices(prim.indices, cat("indices of ", where), n);
    } else {
        source.resize(n);
        for (std::size_t i = 0; i < n; ++i) source[i] = static_cast<std::uint32_t>(i);
    }
    const std::size_t k = source.size();
    if (mode == TINYGLTF_MODE_TRIANGLES) {
        if (k % 3 != 0 || k == 0)
            fail_(cat(where, ": ", k, prim.indices >= 0 ? " indices" : " vertices",
                      " do not form whole triangles (not a multiple of 3)"));
        g.indices = std::move(source);
    } else {
        if (k < 3) fail_(cat(where, ": a triangle strip/fan needs at least 3 vertices, got ", k));
        g.indices.reserve(3 * (k - 2));
        for (std::size_t i = 0; i + 2 < k; ++i) {
            if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
                // glTF 2.0 §3.7.2.1: p_i = {v_i, v_(i+(1+i%2)), v_(i+(2-i%2))}
                const std::size_t odd = i % 2;
                g.indices.insert(g.indices.end(), {source[i], source[i + 1 + odd], source[i + 2 - odd]});
            } else {
                // Fan: p_i = {v_(i+1), v_(i+2), v_0}
                g.indices.insert(g.indices.end(), {source[i + 1], source[i + 2], source[0]});
            }
        }
    }

    // Normals: generated when missing; given ones normalised, zero-length
    // ones replaced by generated normals per vertex.
    if (g.normals.empty()) {
        g.normals = generateVertexNormals(g.positions, g.indices);
    } else {
        std::vector<vec3> generated;
        for (std::size_t i = 0; i < n; ++i) {
            const float len = glm::length(g.normals[i]);
            if (len > 1e-20f && std::isfinite(len)) {
                g.normals[i] /= len;
            } else {
                if (generated.empty()) generated = generateVertexNormals(g.positions, g.indices);
                g.normals[i] = generated[i];
            }
        }
    }

    // Morph targets (TANGENT and other attributes are ignored).
    for (std::size_t t = 0; t < prim.targets.size(); ++t) {
        const auto& target = prim.targets[t];
        MorphTarget mt;
        if (const int a = attribute(target, "POSITION"); a >= 0)
            mt.positionDeltas = readPositionDeltas(a, cat("POSITION of morph target ", t, " of ", where), n);
        if (const int a = attribute(target, "NORMAL"); a >= 0)
            mt.normalDeltas = readNormals(a, cat("NORMAL of morph target ", t, " of ", where), n);
        g.morphTargets.push_back(std::move(mt));
    }

    if (prim.material >= 0) {
        checkIndex(prim.material, m_.materials, "material", where);
        g.material = static_cast<MaterialId>(localMaterial(prim.material));
    } else {
        g.material = static_cast<MaterialId>(defaultMaterial());
    }
    decoded_.clear();
    return g;
}

}  // namespace rtlab::ecs::load::gltf
