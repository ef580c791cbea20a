#pragma once
// The World: entities, their components (sparse sets), the shared assets, and
// the systems that turn explicit writes into a FrameUpdate.
//
// Writes that matter go through patch() (components), deformMesh() /
// replaceMesh() (mesh assets) or patchMaterial(); each feeds a dirty set.
// Direct writes are impossible: get() hands out const references only.
#include <rtlab/ecs/assets.hpp>
#include <rtlab/ecs/component_store.hpp>
#include <rtlab/ecs/components.hpp>
#include <rtlab/ecs/frame_update.hpp>
#include <rtlab/ecs/volume_grid.hpp>

#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <tuple>
#include <type_traits>
#include <utility>
#include <vector>

namespace rtlab::ecs {

// Scene-level settings a scene source may supply (scene .json, builtins).
struct SceneSettings {
    std::string name;
    float frameSeconds = 1.f / 24.f;  // time step between rendered frames
    vec3 backgroundRadiance{0.f};     // radiance of rays that leave the scene
    // A parametric builtin scene's parameters as used (defaults filled in),
    // in the order the scene declares them, and one line on what it generated
    // (e.g. the grid chosen for a requested triangle count). Printed by `rtlab info`.
    std::vector<std::pair<std::string, std::uint32_t>> parameters;
    std::string generated;
};

// What loading left out of the scene: filled by the loaders, printed by
// `rtlab info` and the CLI's warnings, recorded in render's stats.json.
struct LoadReport {
    std::uint32_t skippedPointPrimitives = 0;  // glTF points primitives (rtlab traces triangles)
    std::uint32_t skippedLinePrimitives = 0;   // glTF lines, line loops and line strips
    std::vector<std::string> warnings;         // one line each, naming the file
};

class World {
public:
    World();
    ~World();
    World(const World&) = delete;
    World& operator=(const World&) = delete;

    // ---- entities ---------------------------------------------------------
    Entity create(const std::string& name = "");
    void destroy(Entity e);  // removes its components; children become roots
    bool alive(Entity e) const { return entities_.alive(e); }
    std::uint32_t entityCount() const { return entities_.aliveCount(); }

    // ---- components -------------------------------------------------------
    // Adds or replaces a component (a structural change: marks it dirty).
    template <class T>
    const T& emplace(Entity e, T value) {
        requireAlive(e);
        const T& stored = store<T>().set(e, std::move(value));
        markDirty<T>(e);
        return stored;
    }
    template <class T>
    void remove(Entity e) {
        requireAlive(e);
        if (store<T>().remove(e)) markDirty<T>(e);
    }
    // Read-only access; nullptr when absent or the handle is stale.
    template <class T>
    const T* get(Entity e) const {
        return alive(e) ? store<T>().find(e) : nullptr;
    }
    template <class T>
    bool has(Entity e) const {
        return get<T>(e) != nullptr;
    }
    // The one way to modify a component: edit(T&) runs, then the entity is
    // marked dirty for T. Throws std::logic_error for a stale handle or a
    // missing component.
    template <class T, class Edit>
    void patch(Entity e, Edit&& edit) {
        requireAlive(e);
        T* c = store<T>().find(e);
        if (!c) throw std::logic_error("patch: entity has no such component");
        edit(*c);
        markDirty<T>(e);
    }
    // Calls fn(Entity, const First&, const Rest&...) for every entity having
    // all the components, in First's dense order.
    template <class First, class... Rest, class Fn>
    void each(Fn&& fn) const {
        const ComponentStore<First>& primary = store<First>();
        const auto entities = primary.entities();
        const auto components = primary.components();
        for (std::size_t i = 0; i < entities.size(); ++i) {
            const Entity e = entities[i];
            if ((store<Rest>().contains(e) && ...)) fn(e, components[i], *store<Rest>().find(e)...);
        }
    }
    template <class T>
    std::size_t count() const {
        return store<T>().size();
    }

    // ---- assets -----------------------------------------------------------
    MeshId addMesh(MeshAsset mesh);  // new mesh: rebuilt on the next update
    const MeshAsset& mesh(MeshId id) const { return meshes_.at(id); }
    const std::vector<MeshAsset>& meshes() const { return meshes_; }
    // Changes vertex data only (positions, normals, uv): a refit. If the edit
    // changes vertex or index counts it is treated as a topology change.
    void deformMesh(MeshId id, const std::function<void(MeshAsset&)>& edit);
    // Replaces the mesh, topology included: a rebuild.
    void replaceMesh(MeshId id, MeshAsset mesh);

    MaterialId addMaterial(Material m);
    const std::vector<Material>& materials() const { return materials_; }
    void patchMaterial(MaterialId id, const std::function<void(Material&)>& edit);

    TextureId addTexture(Texture t);
    const std::vector<Texture>& textures() const { return textures_; }

    void addAnimation(AnimationClip clip);
    const std::vector<AnimationClip>& animations() const { return animations_; }
    float animationDuration() const;  // longest clip, seconds

    VolumeId addVolumeGrid(std::shared_ptr<const VolumeGrid> grid);
    const std::vector<std::shared_ptr<const VolumeGrid>>& volumeGrids() const { return volumeGrids_; }

    SceneSettings& settings() { return settings_; }
    const SceneSettings& settings() const { return settings_; }
    LoadReport& loadReport() { return loadReport_; }
    const LoadReport& loadReport() const { return loadReport_; }
    Entity activeCamera() const { return activeCamera_; }
    void setActiveCamera(Entity e) { activeCamera_ = e; }

    // ---- systems ----------------------------------------------------------
    // Advances time by dt seconds and runs, in order: animation sampling,
    // transform propagation, morph targets + CPU skinning. Returns what
    // changed since the previous update (the first update reports every mesh
    // as rebuilt and the instance set as changed).
    FrameUpdate update(float dt);
    float time() const { return time_; }

    // Entities that have a MeshInstance and whose world transform is used for
    // the TLAS (skinned meshes are already in world space: identity).
    mat4 instanceWorldFromObject(Entity e) const;
    // The same, computed from local transforms up the parent chain: valid
    // before the first update() (loaders use it to frame a scene).
    mat4 computeInstanceWorldFromObject(Entity e) const;

private:
    using Stores =
        std::tuple<ComponentStore<Name>, ComponentStore<Parent>, ComponentStore<LocalTransform>,
                   ComponentStore<WorldTransform>, ComponentStore<MeshInstance>, ComponentStore<MorphWeights>,
                   ComponentStore<Skin>, ComponentStore<Light>, ComponentStore<Camera>, ComponentStore<Volume>>;
    template <class T>
    ComponentStore<T>& store() {
        return std::get<ComponentStore<T>>(stores_);
    }
    template <class T>
    const ComponentStore<T>& store() const {
        return std::get<ComponentStore<T>>(stores_);
    }

    void requireAlive(Entity e) const {
        if (!alive(e)) throw std::logic_error("stale or invalid entity handle");
    }
    // Which dirty set a write to component T feeds.
    enum class DirtyKind { None, Transform, Hierarchy, Instance, Morph, Skin, Light, Camera, Volume };
    template <class T>
    static constexpr DirtyKind dirtyKindOf() {
        if constexpr (std::is_same_v<T, LocalTransform>) return DirtyKind::Transform;
        else if constexpr (std::is_same_v<T, Parent>) return DirtyKind::Hierarchy;
        else if constexpr (std::is_same_v<T, MeshInstance>) return DirtyKind::Instance;
        else if constexpr (std::is_same_v<T, MorphWeights>) return DirtyKind::Morph;
        else if constexpr (std::is_same_v<T, Skin>) return DirtyKind::Skin;
        else if constexpr (std::is_same_v<T, Light>) return DirtyKind::Light;
        else if constexpr (std::is_same_v<T, Camera>) return DirtyKind::Camera;
        else if constexpr (std::is_same_v<T, Volume>) return DirtyKind::Volume;
        else return DirtyKind::None;
    }
    template <class T>
    void markDirty(Entity e) {
        static_assert(!std::is_same_v<T, WorldTransform>, "WorldTransform is written by the transform system only");
        markDirty(e, dirtyKindOf<T>());
    }
    void markDirty(Entity e, DirtyKind kind);

    // Systems (ecs/src/systems/*.cpp).
    void runAnimationSystem();
    void runTransformSystem(FrameUpdate& out);
    void runDeformationSystem(FrameUpdate& out);
    void rebuildHierarchyOrder();

    EntityPool entities_;
    Stores stores_;
    std::vector<MeshAsset> meshes_;
    std::vector<Material> materials_;
    std::vector<Texture> textures_;
    std::vector<AnimationClip> animations_;
    std::vector<std::shared_ptr<const VolumeGrid>> volumeGrids_;
    SceneSettings settings_;
    LoadReport loadReport_;
    Entity activeCamera_;

    float time_ = 0.f;
    std::uint32_t frame_ = 0;

    // Dirty sets, cleared by update().
    struct DirtySets;
    std::unique_ptr<DirtySets> dirty_;
    std::vector<Entity> hierarchyOrder_;  // parents before children
    bool hierarchyOrderValid_ = false;
};

}  // namespace rtlab::ecs
