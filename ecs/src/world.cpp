#include "world_dirty_sets.hpp"

#include <rtlab/ecs/world.hpp>

#include <algorithm>

namespace rtlab::ecs {

World::World() : dirty_(std::make_unique<DirtySets>()) {}
World::~World() = default;

Entity World::create(const std::string& name) {
    const Entity e = entities_.create();
    if (!name.empty()) store<Name>().set(e, Name{name});
    store<WorldTransform>().set(e, WorldTransform{});
    dirty_->transforms.insert(e.index);
    hierarchyOrderValid_ = false;
    return e;
}

void World::destroy(Entity e) {
    if (!alive(e)) return;
    if (store<MeshInstance>().contains(e)) dirty_->instanceSet = true;
    if (store<Light>().contains(e)) dirty_->lights = true;
    if (store<Camera>().contains(e)) dirty_->cameras = true;
    // Children of e become roots.
    auto& parents = store<Parent>();
    std::vector<Entity> orphans;
    for (std::size_t i = 0; i < parents.size(); ++i)
        if (parents.components()[i].entity == e) orphans.push_back(parents.entities()[i]);
    for (Entity child : orphans) {
        parents.remove(child);
        dirty_->transforms.insert(child.index);
    }
    std::apply([e](auto&... s) { (s.remove(e), ...); }, stores_);
    entities_.destroy(e);
    hierarchyOrderValid_ = false;
    if (activeCamera_ == e) activeCamera_ = kNullEntity;
}

void World::markDirty(Entity e, DirtyKind kind) {
    switch (kind) {
        case DirtyKind::Hierarchy: hierarchyOrderValid_ = false; [[fallthrough]];
        case DirtyKind::Transform: dirty_->transforms.insert(e.index); break;
        case DirtyKind::Instance:
            dirty_->instanceSet = true;
            dirty_->newInstances.insert(e.index);
            break;
        case DirtyKind::Morph: dirty_->morphWeights.insert(e.index); break;
        case DirtyKind::Skin: dirty_->skins.insert(e.index); break;
        case DirtyKind::Light: dirty_->lights = true; break;
        case DirtyKind::Camera: dirty_->cameras = true; break;
        case DirtyKind::Volume: dirty_->volumes = true; break;
        case DirtyKind::None: break;
    }
}

MeshId World::addMesh(MeshAsset mesh) {
    meshes_.push_back(std::move(mesh));
    const MeshId id = static_cast<MeshId>(meshes_.size() - 1);
    dirty_->rebuiltMeshes.insert(id);
    return id;
}

void World::deformMesh(MeshId id, const std::function<void(MeshAsset&)>& edit) {
    MeshAsset& m = meshes_.at(id);
    // Record the topology so an edit that changes it becomes a rebuild.
    std::vector<std::pair<std::size_t, std::size_t>> counts;
    for (const Geometry& g : m.geometries) counts.emplace_back(g.positions.size(), g.indices.size());
    edit(m);
    bool sameTopology = counts.size() == m.geometries.size();
    for (std::size_t i = 0; sameTopology && i < counts.size(); ++i)
        sameTopology = counts[i] == std::make_pair(m.geometries[i].positions.size(), m.geometries[i].indices.size());
    if (sameTopology) dirty_->refitMeshes.insert(id);
    else dirty_->rebuiltMeshes.insert(id);
}

void World::replaceMesh(MeshId id, MeshAsset mesh) {
    meshes_.at(id) = std::move(mesh);
    dirty_->rebuiltMeshes.insert(id);
}

MaterialId World::addMaterial(Material m) {
    materials_.push_back(std::move(m));
    dirty_->materials = true;
    return static_cast<MaterialId>(materials_.size() - 1);
}

void World::patchMaterial(MaterialId id, const std::function<void(Material&)>& edit) {
    edit(materials_.at(id));
    dirty_->materials = true;
}

TextureId World::addTexture(Texture t) {
    textures_.push_back(std::move(t));
    return static_cast<TextureId>(textures_.size() - 1);
}

void World::addAnimation(AnimationClip clip) { animations_.push_back(std::move(clip)); }

float World::animationDuration() const {
    float d = 0.f;
    for (const AnimationClip& c : animations_) d = std::max(d, c.duration());
    return d;
}

VolumeId World::addVolumeGrid(std::shared_ptr<const VolumeGrid> grid) {
    volumeGrids_.push_back(std::move(grid));
    dirty_->volumes = true;
    return static_cast<VolumeId>(volumeGrids_.size() - 1);
}

mat4 World::instanceWorldFromObject(Entity e) const {
    if (has<Skin>(e)) return mat4(1.f);  // skinned vertices are already in world space
    const WorldTransform* w = get<WorldTransform>(e);
    return w ? w->worldFromObject : mat4(1.f);
}

mat4 World::computeInstanceWorldFromObject(Entity e) const {
    if (has<Skin>(e)) return mat4(1.f);
    mat4 m(1.f);
    std::uint32_t steps = 0;
    for (Entity cur = e; alive(cur) && steps <= entityCount(); ++steps) {
        const LocalTransform* local = get<LocalTransform>(cur);
        if (local) m = local->matrix() * m;
        const Parent* p = get<Parent>(cur);
        if (!p) break;
        cur = p->entity;
    }
    return m;
}

FrameUpdate World::update(float dt) {
    FrameUpdate out;
    out.frame = frame_;
    time_ += dt;
    out.time = time_;

    runAnimationSystem();
    runTransformSystem(out);
    runDeformationSystem(out);

    // Step: collect mesh work; a rebuilt mesh needs no refit as well.
    for (std::uint32_t id : dirty_->rebuiltMeshes.list()) out.rebuiltMeshes.push_back(id);
    for (std::uint32_t id : dirty_->refitMeshes.list())
        if (!dirty_->rebuiltMeshes.contains(id)) out.refitMeshes.push_back(id);
    std::sort(out.rebuiltMeshes.begin(), out.rebuiltMeshes.end());
    std::sort(out.refitMeshes.begin(), out.refitMeshes.end());
    out.instanceSetChanged = dirty_->instanceSet;
    out.lightsChanged = out.lightsChanged || dirty_->lights;
    out.camerasChanged = out.camerasChanged || dirty_->cameras;
    out.materialsChanged = dirty_->materials;

    dirty_->clear();
    ++frame_;
    return out;
}

}  // namespace rtlab::ecs
