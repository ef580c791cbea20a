#pragma once
// Shared by the builtin scene builders (builtin_scenes.cpp: the fixed scenes
// and the parameter parser; scalable_scenes.cpp: terrain, forest, hairball,
// slivers).
#include <rtlab/ecs/world.hpp>

#include <cstdint>
#include <map>
#include <string>

namespace rtlab::ecs::load::builtin {

Material diffuse(const std::string& name, const vec3& albedo);
Entity place(World& world, const std::string& name, MeshId mesh, const vec3& t, const quat& r = quat(1, 0, 0, 0),
             const vec3& s = vec3(1.f));
Entity addLight(World& world, const std::string& name, const Light& light, const vec3& position,
                const vec3& direction = vec3(0.f, -1.f, 0.f));
Entity addCamera(World& world, const vec3& position, const vec3& target, float yfov, float zfar = 100.f);

// A builtin scene's parameter values after parsing and range checks, every
// accepted key present (defaults filled in).
using Parameters = std::map<std::string, std::uint32_t>;

// The scalable scenes (scalable_scenes.cpp). Each records what it generated in
// world.settings().generated.
void buildTerrain(World& world, const Parameters& p);   // "triangles", "seed"
void buildForest(World& world, const Parameters& p);    // "instances", "seed"
void buildHairball(World& world, const Parameters& p);  // "triangles", "seed"
void buildSlivers(World& world, const Parameters& p);   // "triangles", "seed"

}  // namespace rtlab::ecs::load::builtin
