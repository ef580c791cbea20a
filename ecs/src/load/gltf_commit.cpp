// Stage 4 of the glTF loader: the staged textures, materials, meshes, entities, skins and animations are
// added to the World. Nothing here can fail on bad input, so a throwing load leaves the World untouched.
#include "gltf_internal.hpp"

#include <cstddef>
#include <utility>
#include <vector>

namespace rtlab::ecs::load::gltf {

std::vector<Entity> commit(World& world, Staged&& s, Entity parent) {
    std::vector<TextureId> textureIds;
    textureIds.reserve(s.textures.size());
    for (Texture& t : s.textures) textureIds.push_back(world.addTexture(std::move(t)));

    std::vector<MaterialId> materialIds;
    materialIds.reserve(s.materials.size());
    for (Material& m : s.materials) {
        if (m.baseColorTexture != kNoTexture) m.baseColorTexture = textureIds[m.baseColorTexture];
        materialIds.push_back(world.addMaterial(std::move(m)));
    }

    std::vector<MeshId> meshIds;
    meshIds.reserve(s.meshes.size());
    for (MeshAsset& mesh : s.meshes) {
        for (Geometry& g : mesh.geometries) g.material = materialIds[g.material];
        meshIds.push_back(world.addMesh(std::move(mesh)));
    }

    const bool parentAlive = world.alive(parent);
    std::vector<Entity> entities(s.nodes.size());
    for (std::size_t i = 0; i < s.nodes.size(); ++i) {
        StagedNode& n = s.nodes[i];
        const Entity e = world.create(n.name);
        entities[i] = e;
        world.emplace(e, n.local);
        if (n.parent >= 0) world.emplace(e, Parent{entities[static_cast<std::size_t>(n.parent)]});
        else if (parentAlive) world.emplace(e, Parent{parent});
        if (n.mesh >= 0) world.emplace(e, MeshInstance{meshIds[static_cast<std::size_t>(n.mesh)]});
        if (n.morph) world.emplace(e, std::move(*n.morph));
        if (n.camera) {
            world.emplace(e, *n.camera);
            if (!world.alive(world.activeCamera())) world.setActiveCamera(e);
        }
        if (n.light) world.emplace(e, *n.light);
    }
    auto entityOf = [&](int gltfNode) {
        const int slot = s.nodeSlot[static_cast<std::size_t>(gltfNode)];
        return slot < 0 ? kNullEntity : entities[static_cast<std::size_t>(slot)];
    };
    for (std::size_t i = 0; i < s.nodes.size(); ++i) {
        const StagedNode& n = s.nodes[i];
        if (n.skin < 0) continue;
        const StagedSkin& skin = *s.skins[static_cast<std::size_t>(n.skin)];
        Skin component;
        for (int j : skin.jointNodes) component.joints.push_back(entityOf(j));
        component.inverseBindMatrices = skin.inverseBind;
        world.emplace(entities[i], std::move(component));
    }
    for (StagedClip& c : s.clips) {
        AnimationClip clip;
        clip.name = std::move(c.name);
        for (StagedChannel& ch : c.channels) {
            ch.channel.target = entityOf(ch.gltfNode);
            clip.channels.push_back(std::move(ch.channel));
        }
        world.addAnimation(std::move(clip));
    }

    std::vector<Entity> roots;
    roots.reserve(s.roots.size());
    for (int r : s.roots) roots.push_back(entities[static_cast<std::size_t>(r)]);
    return roots;
}

}  // namespace rtlab::ecs::load::gltf
