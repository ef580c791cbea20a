#include <rtlab/rtcore_sim/model_scene.hpp>
#include <rtlab/tracer/conservative_bounds.hpp>
#include <rtlab/tracer/instance_transform.hpp>

#include <algorithm>
#include <cmath>

namespace rtlab::rtcore_sim {

ModelScene::ModelScene(BvhParams params) : params_(params), device_(0), builder_(device_.get()) {}

void ModelScene::buildBlasOf(const ecs::MeshAsset& mesh, ecs::MeshId id) {
    if (blases_.size() <= id) blases_.resize(id + 1);
    blases_[id] = std::make_unique<Blas>(buildBlas(builder_, mesh, params_));
}

ModelUpdateStats ModelScene::update(const ecs::SceneSnapshot& scene) {
    ModelUpdateStats stats;
    ++generation_;
    const ecs::FrameUpdate& u = scene.update;
    const std::vector<ecs::MeshAsset>& meshes = *scene.meshes;
    std::vector<std::uint8_t> touched(meshes.size(), 0);

    // Step: rebuilds, exactly what the FrameUpdate lists.
    for (ecs::MeshId id : u.rebuiltMeshes) {
        buildBlasOf(meshes.at(id), id);
        touched[id] = 1;
        ++stats.blasRebuilt;
    }
    // Step: refits, turned into rebuilds when the refit tree has degraded too much.
    for (ecs::MeshId id : u.refitMeshes) {
        if (touched[id]) continue;
        touched[id] = 1;
        Blas* blas = id < blases_.size() ? blases_[id].get() : nullptr;
        if (!blas) {  // never built: build instead
            buildBlasOf(meshes.at(id), id);
            ++stats.blasRebuilt;
            continue;
        }
        refitBlas(*blas, meshes.at(id));
        const double cost = blas->bvh.sahCost(params_.sahTraversalCost, params_.sahIntersectionCost);
        const double degradation = blas->buildSahCost > 0.0 ? cost / blas->buildSahCost : 1.0;
        stats.worstRefitDegradation = std::max(stats.worstRefitDegradation, static_cast<float>(degradation));
        if (params_.refitRebuildThreshold > 0.f && degradation > params_.refitRebuildThreshold) {
            buildBlasOf(meshes.at(id), id);
            ++stats.blasRebuilt;
            ++stats.blasRebuiltForQuality;
        } else {
            ++stats.blasRefit;
        }
    }
    for (std::size_t id = 0; id < meshes.size(); ++id)
        if (!touched[id] && id < blases_.size() && blases_[id]) ++stats.blasReused;

    // Step: TLAS over the instances' world boxes, whenever geometry changed.
    if (!tlasBuilt_ || u.geometryChanged()) rebuildTlas(scene, stats);
    return stats;
}

void ModelScene::rebuildTlas(const ecs::SceneSnapshot& scene, ModelUpdateStats& stats) {
    const std::vector<ecs::MeshAsset>& meshes = *scene.meshes;
    instances_.clear();
    instances_.reserve(scene.instances.size());
    std::vector<BuildPrimitive> prims;
    double magnitude = 0.0, conditioning = 1.0;
    for (std::uint32_t i = 0; i < scene.instances.size(); ++i) {
        const ecs::InstanceSnapshot& s = scene.instances[i];
        if (!blas(s.mesh)) {  // not listed in any FrameUpdate yet: build on first use
            buildBlasOf(meshes.at(s.mesh), s.mesh);
            ++stats.blasRebuilt;
        }
        ModelInstance inst;
        inst.mesh = s.mesh;
        inst.worldFromObject = s.worldFromObject;
        inst.objectFromWorld = tracer::objectFromWorldOf(s.worldFromObject);
        inst.mask = s.mask;
        const Bvh& bvh = blases_[s.mesh]->bvh;
        if (!bvh.empty()) inst.worldBounds = bvh.rootBounds.transformed(s.worldFromObject);
        // Step: what this instance brings to the TLAS's conservative padding.
        const double objectToWorld = maxNormGain(s.worldFromObject);
        const double kappa = objectToWorld * maxNormGain(inst.objectFromWorld);
        if (!bvh.empty() && std::isfinite(kappa)) {
            const double reach = std::max({double(tracer::maxAbsCoordinate(inst.worldBounds)),
                                           objectToWorld * blases_[s.mesh]->magnitude,
                                           double(tracer::maxAbsCoordinate(vec3(s.worldFromObject[3])))});
            magnitude = std::max(magnitude, kappa * reach);
            conditioning = std::max(conditioning, kappa);
        }
        // Instances with nothing to hit stay out of the TLAS (Embree skips them too).
        if (!inst.worldBounds.empty() && isFinite(inst.worldBounds.lo) && isFinite(inst.worldBounds.hi))
            prims.push_back(BuildPrimitive{inst.worldBounds, PrimitiveRef{0, i}});
        instances_.push_back(inst);
    }
    tlas_ = builder_.build(prims, tlasBuildSettings(params_));
    tlasMagnitude_ = static_cast<float>(magnitude);
    tlasConditioning_ = static_cast<float>(conditioning);
    tlasBuilt_ = true;
    ++stats.tlasBuilds;
    stats.instancesMoved = static_cast<std::uint32_t>(scene.update.movedInstances.size());
}

}  // namespace rtlab::rtcore_sim
