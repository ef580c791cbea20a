#pragma once
// Components: plain structs stored in sparse sets by the World. Only the
// World's systems write WorldTransform; everything else is written through
// World::patch(), which feeds the dirty sets.
#include <rtlab/core/math.hpp>
#include <rtlab/ecs/assets.hpp>
#include <rtlab/ecs/entity.hpp>

#include <string>
#include <vector>

namespace rtlab::ecs {

struct Name {
    std::string value;
};

// Scene-graph parent; absent for roots.
struct Parent {
    Entity entity;
};

// Local translation / rotation / scale relative to the parent.
struct LocalTransform {
    vec3 translation{0.f};
    quat rotation{1.f, 0.f, 0.f, 0.f};  // w, x, y, z
    vec3 scale{1.f};
    mat4 matrix() const { return composeTrs(translation, rotation, scale); }
};

// Written by the transform system only.
struct WorldTransform {
    mat4 worldFromObject{1.f};
};

// Places a mesh asset in the world (one TLAS instance).
struct MeshInstance {
    static constexpr std::uint32_t kAutomatic = 0xffffffffu;
    MeshId mesh = 0;
    std::uint8_t mask = 0xff;                   // DXR InstanceMask
    std::uint8_t flags = 0;                     // DXR instance flags (tracer::InstanceFlag)
    std::uint32_t instanceId = kAutomatic;      // DXR InstanceID() (24 bit); automatic = entity index
    std::uint32_t hitGroupOffset = kAutomatic;  // InstanceContributionToHitGroupIndex; automatic = from the SBT layout
};

// Current morph-target weights of the instance's mesh.
struct MorphWeights {
    std::vector<float> weights;
};

// glTF skin: the instance's mesh is deformed by these joints.
struct Skin {
    std::vector<Entity> joints;
    std::vector<mat4> inverseBindMatrices;  // one per joint
};

enum class LightType : std::uint8_t { Point, Spot, Directional, Rect, Sphere };

// Lights emit along the entity's local -Z (spot, directional, rect). A rect
// light spans size.x x size.y in its local XY plane, centred on its origin.
struct Light {
    LightType type = LightType::Point;
    vec3 color{1.f};
    float intensity = 1.f;  // candela (point/spot), lux (directional), nits (area)
    float range = 0.f;      // 0 = unlimited
    float innerConeAngle = 0.f;
    float outerConeAngle = kPi / 4.f;
    vec2 size{1.f};      // rect light width, height
    float radius = 0.f;  // sphere light radius
    bool isArea() const { return type == LightType::Rect || type == LightType::Sphere; }
};

// Perspective camera looking down local -Z.
struct Camera {
    float yfov = 0.8f;  // radians
    float znear = 0.01f;
    float zfar = 1000.f;
    float aspectRatio = 0.f;  // 0 = from the image
};

// A participating medium from a volume grid asset.
struct Volume {
    VolumeId grid = 0;
    float densityScale = 1.f;
    vec3 albedo{0.8f};
};

}  // namespace rtlab::ecs
