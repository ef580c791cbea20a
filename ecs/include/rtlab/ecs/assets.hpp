#pragma once
// Shared assets referenced by components: meshes (geometry + deformation
// sources), materials, textures, animation clips, volume grids.
// Plain data: the tracer reads these through a SceneSnapshot.
#include <rtlab/core/math.hpp>
#include <rtlab/ecs/entity.hpp>

#include <algorithm>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace rtlab::ecs {

using MeshId = std::uint32_t;
using MaterialId = std::uint32_t;
using TextureId = std::uint32_t;
using VolumeId = std::uint32_t;
inline constexpr std::uint32_t kNoTexture = 0xffffffffu;

struct MorphTarget {
    std::vector<vec3> positionDeltas;  // empty or one per vertex
    std::vector<vec3> normalDeltas;    // empty or one per vertex
};

// One triangle list with one material (a glTF primitive; a DXR geometry).
struct Geometry {
    std::vector<vec3> positions;
    std::vector<vec3> normals;  // one per vertex, unit length
    std::vector<vec2> uv0;      // empty or one per vertex
    // Empty or one per vertex: linear RGBA multiplying the material's base
    // colour (glTF COLOR_0, OBJ's "v x y z r g b", PLY and FBX vertex colours).
    std::vector<vec4> colors;
    std::vector<std::uint32_t> indices;  // 3 per triangle, all < positions.size()
    MaterialId material = 0;

    // Deformation sources; empty for rigid geometry. When present, positions
    // and normals are outputs of the deformation system.
    std::vector<vec3> restPositions;
    std::vector<vec3> restNormals;
    std::vector<MorphTarget> morphTargets;
    std::vector<glm::uvec4> joints;  // skin joint indices (into Skin::joints)
    std::vector<vec4> weights;       // skin weights, summing to 1

    // Procedural geometry (DXR AABBs + intersection shader) when non-empty;
    // positions/indices are then unused.
    std::vector<Aabb> proceduralBoxes;

    std::size_t triangleCount() const { return indices.size() / 3; }
    bool procedural() const { return !proceduralBoxes.empty(); }
    bool deformable() const { return !morphTargets.empty() || !joints.empty(); }
};

// A mesh asset: one bottom-level acceleration structure, many instances.
struct MeshAsset {
    std::string name;
    std::vector<Geometry> geometries;

    std::size_t triangleCount() const {
        std::size_t n = 0;
        for (const Geometry& g : geometries) n += g.triangleCount();
        return n;
    }
    Aabb bounds() const {
        Aabb b;
        for (const Geometry& g : geometries) {
            for (const vec3& p : g.positions) b.extend(p);
            for (const Aabb& box : g.proceduralBoxes) b.extend(box);
        }
        return b;
    }
};

enum class AlphaMode : std::uint8_t { Opaque, Mask, Blend };

// glTF metallic-roughness material plus KHR_materials_transmission / _ior /
// _volume (attenuation) parameters.
struct Material {
    std::string name;
    vec4 baseColor{1.f};
    TextureId baseColorTexture = kNoTexture;
    float metallic = 0.f;
    float roughness = 1.f;
    vec3 emissive{0.f};
    AlphaMode alphaMode = AlphaMode::Opaque;
    float alphaCutoff = 0.5f;
    float transmission = 0.f;
    float ior = 1.5f;
    vec3 attenuationColor{1.f};
    float attenuationDistance = kInfinity;
    bool doubleSided = false;
};

// 8-bit RGBA texture, row-major, top row first.
struct Texture {
    std::string name;
    int width = 0;
    int height = 0;
    bool srgb = true;
    std::vector<std::uint8_t> rgba8;
};

enum class AnimationPath : std::uint8_t { Translation, Rotation, Scale, Weights };
enum class Interpolation : std::uint8_t { Step, Linear, CubicSpline };

// One glTF animation channel with its sampler, values flattened:
// `componentsPerKey` floats per key (x3 for CubicSpline: in-tangent, value, out-tangent).
struct AnimationChannel {
    Entity target;
    AnimationPath path = AnimationPath::Translation;
    Interpolation interpolation = Interpolation::Linear;
    std::vector<float> times;  // non-decreasing, seconds
    std::vector<float> values;
    std::uint32_t componentsPerKey = 3;  // 3 (T,S), 4 (R, quaternion xyzw), N (morph weights)
};

struct AnimationClip {
    std::string name;
    std::vector<AnimationChannel> channels;
    float duration() const {
        float d = 0.f;
        for (const AnimationChannel& c : channels)
            if (!c.times.empty()) d = std::max(d, c.times.back());
        return d;
    }
};

}  // namespace rtlab::ecs
