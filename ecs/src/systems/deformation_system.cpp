// Morph targets and CPU linear-blend skinning. A mesh whose weights or joints
// changed this update is re-evaluated from its rest pose and reported as a
// refit (same topology).
#include "../world_dirty_sets.hpp"

namespace rtlab::ecs {
namespace {

void evaluateGeometry(Geometry& g, const std::vector<float>* morphWeights, const std::vector<mat4>* jointMatrices) {
    if (g.restPositions.empty()) return;
    const std::size_t n = g.restPositions.size();
    const bool hasNormals = g.restNormals.size() == n;
    g.positions = g.restPositions;
    if (hasNormals) g.normals = g.restNormals;
    // Step: morph targets, p = rest + sum_i w_i * delta_i.
    if (morphWeights) {
        for (std::size_t t = 0; t < g.morphTargets.size() && t < morphWeights->size(); ++t) {
            const float w = (*morphWeights)[t];
            if (w == 0.f) continue;
            const MorphTarget& target = g.morphTargets[t];
            if (target.positionDeltas.size() == n)
                for (std::size_t v = 0; v < n; ++v) g.positions[v] += w * target.positionDeltas[v];
            if (hasNormals && target.normalDeltas.size() == n)
                for (std::size_t v = 0; v < n; ++v) g.normals[v] += w * target.normalDeltas[v];
        }
    }
    // Step: skinning, p' = (sum_k w_k * worldFromJoint_k * inverseBind_k) p.
    if (jointMatrices && g.joints.size() == n && g.weights.size() == n) {
        for (std::size_t v = 0; v < n; ++v) {
            mat4 m(0.f);
            for (int k = 0; k < 4; ++k) {
                const float w = g.weights[v][k];
                const std::uint32_t j = g.joints[v][k];
                if (w != 0.f && j < jointMatrices->size()) m += w * (*jointMatrices)[j];
            }
            g.positions[v] = vec3(m * vec4(g.positions[v], 1.f));
            if (hasNormals) g.normals[v] = mat3(m) * g.normals[v];
        }
    }
    if (hasNormals)
        for (vec3& nrm : g.normals) {
            const float len = glm::length(nrm);
            nrm = len > 0.f && std::isfinite(len) ? nrm / len : vec3(0.f, 0.f, 1.f);
        }
}

}  // namespace

void World::runDeformationSystem(FrameUpdate&) {
    const auto& changed = dirty_->worldChanged;
    std::vector<mat4> jointMatrices;
    each<MeshInstance>([&](Entity e, const MeshInstance& inst) {
        const MorphWeights* morph = get<MorphWeights>(e);
        const Skin* skin = get<Skin>(e);
        if (!morph && !skin) return;
        // Step: does anything that drives this mesh's vertices differ from last update?
        bool dirty = dirty_->morphWeights.contains(e.index) || dirty_->skins.contains(e.index) ||
                     dirty_->rebuiltMeshes.contains(inst.mesh);
        if (skin && !dirty)
            for (Entity j : skin->joints)
                if (alive(j) && j.index < changed.size() && changed[j.index]) {
                    dirty = true;
                    break;
                }
        if (!dirty || inst.mesh >= meshes_.size()) return;

        if (skin) {
            jointMatrices.resize(skin->joints.size());
            for (std::size_t j = 0; j < skin->joints.size(); ++j) {
                const WorldTransform* w = get<WorldTransform>(skin->joints[j]);
                const mat4 inverseBind =
                    j < skin->inverseBindMatrices.size() ? skin->inverseBindMatrices[j] : mat4(1.f);
                jointMatrices[j] = (w ? w->worldFromObject : mat4(1.f)) * inverseBind;
            }
        }
        for (Geometry& g : meshes_[inst.mesh].geometries)
            evaluateGeometry(g, morph ? &morph->weights : nullptr, skin ? &jointMatrices : nullptr);
        dirty_->refitMeshes.insert(inst.mesh);
    });
}

}  // namespace rtlab::ecs
