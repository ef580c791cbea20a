// Stage 3 of the glTF loader, the scene graph: GltfConverter::convert (the stage's driver), the node
// hierarchy and scene roots, node transforms, skins, and the cameras and lights nodes carry.
#define GLM_ENABLE_EXPERIMENTAL

#include "gltf_internal.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace rtlab::ecs::load::gltf {

Staged GltfConverter::convert() {
    s_.nodeSlot.assign(m_.nodes.size(), -1);
    s_.skins.resize(m_.skins.size());
    materialSlot_.assign(m_.materials.size(), -1);
    imageSlot_.assign(m_.images.size(), -2);  // -2: not converted yet
    baseMeshes_.resize(m_.meshes.size());
    quantized_ = std::find(m_.extensionsUsed.begin(), m_.extensionsUsed.end(), "KHR_mesh_quantization") !=
                 m_.extensionsUsed.end();

    validateHierarchy();
    const std::vector<int> roots = sceneRoots();
    checkDeclaredGeometry(roots);
    traverse(roots);
    convertAnimations();
    return std::move(s_);
}

void GltfConverter::validateHierarchy() {
    const int n = static_cast<int>(m_.nodes.size());
    parentOf_.assign(m_.nodes.size(), -1);
    for (int i = 0; i < n; ++i) {
        for (int c : m_.nodes[static_cast<std::size_t>(i)].children) {
            checkIndex(c, m_.nodes, "child node", nodeLabel(i));
            if (c == i) fail_(cat(nodeLabel(i), " lists itself as a child (node cycle)"));
            int& p = parentOf_[static_cast<std::size_t>(c)];
            if (p != -1)
                fail_(cat(nodeLabel(c), " is a child of both node ", p, " and node ", i,
                          " (the node hierarchy must be a tree)"));
            p = i;
        }
    }
    // Every node has at most one parent now; a node that cannot be reached
    // from a parentless node sits on a cycle.
    std::vector<std::uint8_t> reached(m_.nodes.size(), 0);
    std::vector<int> stack;
    for (int i = 0; i < n; ++i)
        if (parentOf_[static_cast<std::size_t>(i)] == -1) stack.push_back(i);
    while (!stack.empty()) {
        const int i = stack.back();
        stack.pop_back();
        reached[static_cast<std::size_t>(i)] = 1;
        for (int c : m_.nodes[static_cast<std::size_t>(i)].children) stack.push_back(c);
    }
    for (int i = 0; i < n; ++i)
        if (!reached[static_cast<std::size_t>(i)]) fail_(cat("node hierarchy contains a cycle through ", nodeLabel(i)));
}

std::vector<int> GltfConverter::sceneRoots() const {
    int sceneIndex = m_.defaultScene;
    if (sceneIndex < 0 && !m_.scenes.empty()) sceneIndex = 0;
    if (sceneIndex >= 0 && m_.scenes.empty()) sceneIndex = -1;  // `scene` without `scenes`: see file comment
    std::vector<int> roots;
    if (sceneIndex < 0) {
        for (std::size_t i = 0; i < m_.nodes.size(); ++i)
            if (parentOf_[i] == -1) roots.push_back(static_cast<int>(i));
        return roots;
    }
    checkIndex(sceneIndex, m_.scenes, "scene", "the default scene");
    std::vector<std::uint8_t> seen(m_.nodes.size(), 0);
    for (int r : m_.scenes[static_cast<std::size_t>(sceneIndex)].nodes) {
        checkIndex(r, m_.nodes, "node", cat("scene ", sceneIndex));
        if (parentOf_[static_cast<std::size_t>(r)] != -1)
            fail_(cat("scene ", sceneIndex, " lists ", nodeLabel(r), " as a root, but it is a child of node ",
                      parentOf_[static_cast<std::size_t>(r)]));
        if (seen[static_cast<std::size_t>(r)]) fail_(cat("scene ", sceneIndex, " lists ", nodeLabel(r), " twice"));
        seen[static_cast<std::size_t>(r)] = 1;
        roots.push_back(r);
    }
    return roots;
}

// Iterative pre-order traversal: parents are staged before children.
void GltfConverter::traverse(const std::vector<int>& roots) {
    std::vector<std::pair<int, int>> stack;  // (glTF node, staged parent)
    for (auto it = roots.rbegin(); it != roots.rend(); ++it) stack.emplace_back(*it, -1);
    while (!stack.empty()) {
        const auto [gltfNode, parent] = stack.back();
        stack.pop_back();
        const int slot = static_cast<int>(s_.nodes.size());
        s_.nodes.push_back(stageNode(gltfNode, parent));
        s_.nodeSlot[static_cast<std::size_t>(gltfNode)] = slot;
        if (parent < 0) s_.roots.push_back(slot);
        const auto& children = m_.nodes[static_cast<std::size_t>(gltfNode)].children;
        for (auto it = children.rbegin(); it != children.rend(); ++it) stack.emplace_back(*it, slot);
    }
}

StagedNode GltfConverter::stageNode(int index, int parent) {
    const tg::Node& node = m_.nodes[static_cast<std::size_t>(index)];
    StagedNode out;
    out.gltfNode = index;
    out.parent = parent;
    out.name = node.name.empty() ? cat("node ", index) : node.name;
    out.local = nodeTransform(index);

    if (node.skin >= 0) {
        checkIndex(node.skin, m_.skins, "skin", nodeLabel(index));
        if (node.mesh < 0) fail_(cat(nodeLabel(index), " has a skin but no mesh"));
    }
    if (node.mesh >= 0) {
        checkIndex(node.mesh, m_.meshes, "mesh", nodeLabel(index));
        stageInstance(index, out);
    } else if (!node.weights.empty()) {
        fail_(cat(nodeLabel(index), " has morph weights but no mesh"));
    }
    if (node.camera >= 0) {
        checkIndex(node.camera, m_.cameras, "camera", nodeLabel(index));
        out.camera = convertCamera(node.camera);
    }
    if (const auto it = node.extensions.find("KHR_lights_punctual"); it != node.extensions.end()) {
        const tg::Value& ext = it->second;
        if (!ext.IsObject() || !ext.Get("light").IsNumber())
            fail_(cat(nodeLabel(index), ": KHR_lights_punctual needs a light index"));
        const double l = ext.Get("light").GetNumberAsDouble();
        if (!(l >= 0.0 && l < static_cast<double>(m_.lights.size())) || l != std::floor(l))
            fail_(cat(nodeLabel(index), " references light ", l, " but the file has ", m_.lights.size()));
        out.light = convertLight(static_cast<int>(l));
    }
    return out;
}

LocalTransform GltfConverter::nodeTransform(int index) const {
    const tg::Node& node = m_.nodes[static_cast<std::size_t>(index)];
    auto finite = [&](const std::vector<double>& v, const char* what) {
        for (double d : v)
            if (!std::isfinite(d) || std::abs(d) > 3.0e38) fail_(cat(nodeLabel(index), ": non-finite ", what));
    };
    LocalTransform t;
    if (!node.matrix.empty()) {
        if (node.matrix.size() != 16) fail_(cat(nodeLabel(index), ": matrix must have 16 elements"));
        finite(node.matrix, "matrix");
        mat4 m(1.f);
        for (int c = 0; c < 4; ++c)
            for (int r = 0; r < 4; ++r) m[c][r] = static_cast<float>(node.matrix[static_cast<std::size_t>(c * 4 + r)]);
        if (m[0][3] != 0.f || m[1][3] != 0.f || m[2][3] != 0.f || m[3][3] != 1.f)
            fail_(cat(nodeLabel(index), ": matrix has a projective part (last row must be 0 0 0 1)"));
        t = localTransformOf(m);
        return t;
    }
    if (!node.translation.empty()) {
        if (node.translation.size() != 3) fail_(cat(nodeLabel(index), ": translation must have 3 elements"));
        finite(node.translation, "translation");
        t.translation = vec3(node.translation[0], node.translation[1], node.translation[2]);
    }
    if (!node.rotation.empty()) {
        if (node.rotation.size() != 4) fail_(cat(nodeLabel(index), ": rotation must have 4 elements"));
        finite(node.rotation, "rotation");
        const quat q(static_cast<float>(node.rotation[3]), static_cast<float>(node.rotation[0]),
                     static_cast<float>(node.rotation[1]), static_cast<float>(node.rotation[2]));
        const float len = glm::length(q);
        if (!(len > 0.f) || !std::isfinite(len)) fail_(cat(nodeLabel(index), ": rotation quaternion has zero length"));
        t.rotation = q / len;
    }
    if (!node.scale.empty()) {
        if (node.scale.size() != 3) fail_(cat(nodeLabel(index), ": scale must have 3 elements"));
        finite(node.scale, "scale");
        t.scale = vec3(node.scale[0], node.scale[1], node.scale[2]);
    }
    return t;
}

const StagedSkin& GltfConverter::stageSkin(int index) {
    std::optional<StagedSkin>& slot = s_.skins[static_cast<std::size_t>(index)];
    if (slot) return *slot;
    const tg::Skin& skin = m_.skins[static_cast<std::size_t>(index)];
    const std::string label = skin.name.empty() ? cat("skin ", index) : cat("skin ", index, " '", skin.name, "'");
    if (skin.joints.empty()) fail_(cat(label, " has no joints"));
    StagedSkin out;
    for (int j : skin.joints) {
        checkIndex(j, m_.nodes, "joint node", label);
        out.jointNodes.push_back(j);
    }
    if (skin.skeleton >= 0) checkIndex(skin.skeleton, m_.nodes, "skeleton node", label);
    out.inverseBind.assign(skin.joints.size(), mat4(1.f));
    if (skin.inverseBindMatrices >= 0) {
        const std::string what = cat("inverseBindMatrices of ", label);
        const AccessorView v = view(skin.inverseBindMatrices, what, {TINYGLTF_TYPE_MAT4}, {{kFloat}}, "MAT4 float");
        if (v.count < skin.joints.size())
            fail_(cat("accessor ", v.index, " (", what, ") has ", v.count, " matrices for ", skin.joints.size(),
                      " joints"));
        const std::vector<float> f = readFloats(v, what);
        for (std::size_t j = 0; j < skin.joints.size(); ++j)
            for (int c = 0; c < 4; ++c)
                for (int r = 0; r < 4; ++r) out.inverseBind[j][c][r] = f[j * 16 + static_cast<std::size_t>(c * 4 + r)];
    }
    slot = std::move(out);
    return *slot;
}

Camera GltfConverter::convertCamera(int index) const {
    const tg::Camera& cam = m_.cameras[static_cast<std::size_t>(index)];
    const std::string label = cam.name.empty() ? cat("camera ", index) : cat("camera ", index, " '", cam.name, "'");
    auto finite = [&](double v, const char* what) {
        if (!std::isfinite(v) || std::abs(v) > 3.0e38) fail_(cat(label, ": ", what, " is not finite"));
        return static_cast<float>(v);
    };
    Camera out;
    if (cam.type == "perspective") {
        const tg::PerspectiveCamera& p = cam.perspective;
        const float yfov = finite(p.yfov, "yfov"), znear = finite(p.znear, "znear");
        const float zfar = finite(p.zfar, "zfar"), aspect = finite(p.aspectRatio, "aspectRatio");
        if (!(yfov > 0.f)) fail_(cat(label, ": yfov must be > 0"));
        if (!(znear > 0.f)) fail_(cat(label, ": znear must be > 0"));
        if (zfar != 0.f && !(zfar > znear)) fail_(cat(label, ": zfar must be greater than znear"));
        if (aspect < 0.f) fail_(cat(label, ": aspectRatio must be > 0"));
        out.yfov = std::min(yfov, kPi - 1e-3f);
        out.znear = znear;
        out.zfar = zfar == 0.f ? kInfiniteFar : zfar;  // glTF: no zfar = infinite projection
        out.aspectRatio = aspect;
    } else if (cam.type == "orthographic") {
        // Approximated as perspective: Camera has no orthographic mode.
        const tg::OrthographicCamera& o = cam.orthographic;
        const float xmag = finite(o.xmag, "xmag"), ymag = finite(o.ymag, "ymag");
        const float znear = finite(o.znear, "znear"), zfar = finite(o.zfar, "zfar");
        if (!(zfar > znear) || znear < 0.f) fail_(cat(label, ": needs 0 <= znear < zfar"));
        out.yfov = 0.8f;
        out.znear = znear > 0.f ? znear : std::min(0.01f, 0.5f * zfar);
        out.zfar = zfar;
        out.aspectRatio = (xmag != 0.f && ymag != 0.f) ? std::abs(xmag / ymag) : 0.f;
    } else {
        fail_(cat(label, ": unknown camera type '", cam.type, "'"));
    }
    return out;
}

Light GltfConverter::convertLight(int index) const {
    const tg::Light& l = m_.lights[static_cast<std::size_t>(index)];
    const std::string label = l.name.empty() ? cat("light ", index) : cat("light ", index, " '", l.name, "'");
    Light out;
    if (l.type == "point") out.type = LightType::Point;
    else if (l.type == "spot") out.type = LightType::Spot;
    else if (l.type == "directional") out.type = LightType::Directional;
    else fail_(cat(label, ": unknown KHR_lights_punctual type '", l.type, "'"));
    if (!l.color.empty()) {
        if (l.color.size() != 3) fail_(cat(label, ": color must have 3 elements"));
        for (int c = 0; c < 3; ++c)
            out.color[c] = factor(l.color[static_cast<std::size_t>(c)], 0.f, 3.0e38f, cat(label, " color"));
    }
    out.intensity = factor(l.intensity, 0.f, 3.0e38f, cat(label, " intensity"));
    out.range = factor(l.range, 0.f, 3.0e38f, cat(label, " range"));  // 0 = unlimited
    if (out.type == LightType::Spot) {
        const float outer = factor(l.spot.outerConeAngle, 1e-4f, kPi / 2.f, cat(label, " outerConeAngle"));
        out.outerConeAngle = outer;
        out.innerConeAngle = factor(l.spot.innerConeAngle, 0.f, outer, cat(label, " innerConeAngle"));
    }
    return out;
}

}  // namespace rtlab::ecs::load::gltf
