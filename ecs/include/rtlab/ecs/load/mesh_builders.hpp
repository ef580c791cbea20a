#pragma once
// Procedural triangle meshes for builtin scenes and tests. Every builder
// returns one Geometry with unit normals, UV0 and counter-clockwise front
// faces (seen from outside, or from inside for `inwardRoom`).
#include <rtlab/ecs/assets.hpp>

namespace rtlab::ecs::load {

// Axis-aligned box centred at the origin with the given full size; flat
// shaded (24 vertices, 12 triangles).
Geometry makeBox(const vec3& size, MaterialId material);
// Closed icosphere of radius r, subdivided `levels` times (20 * 4^levels
// triangles), vertices shared between faces (watertight).
Geometry makeIcosphere(float radius, int levels, MaterialId material);
// Square in the XZ plane facing +Y, side `size`, n x n quads.
Geometry makeGrid(float size, int n, MaterialId material);
// Quad in the XY plane facing +Z, width x height.
Geometry makeQuad(float width, float height, MaterialId material);

// Surface of revolution about +Y: the polyline `profile` of (radius, y)
// points swept through `segments` angular steps. Bands whose two rings both
// have radius 0 are skipped, a band with one zero-radius ring becomes a fan
// (no degenerate triangles); normals are area-weighted vertex normals.
Geometry makeLathe(const std::vector<vec2>& profile, int segments, MaterialId material);

MeshAsset makeMesh(std::string name, Geometry g);

}  // namespace rtlab::ecs::load
