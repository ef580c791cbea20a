#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <algorithm>
#include <map>
#include <utility>

namespace rtlab::ecs::load {

Geometry makeBox(const vec3& size, MaterialId material) {
    Geometry g;
    g.material = material;
    const vec3 h = 0.5f * size;
    // Step: one face per axis direction, 4 vertices each so normals stay flat.
    const vec3 normals[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    for (const vec3& n : normals) {
        // Tangent frame with u x v = n so (0,1,2),(0,2,3) winds counter-clockwise.
        const vec3 u = std::abs(n.y) > 0.5f ? vec3(1, 0, 0) * n.y : vec3(-n.z, 0, n.x);
        const vec3 v = glm::cross(n, u);
        const std::uint32_t base = static_cast<std::uint32_t>(g.positions.size());
        const vec2 corners[4] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
        for (const vec2& c : corners) {
            g.positions.push_back(h * (n + c.x * u + c.y * v));
            g.normals.push_back(n);
            g.uv0.push_back(0.5f * (c + 1.f));
        }
        for (std::uint32_t i : {0u, 1u, 2u, 0u, 2u, 3u}) g.indices.push_back(base + i);
    }
    return g;
}

Geometry makeIcosphere(float radius, int levels, MaterialId material) {
    const float t = (1.f + std::sqrt(5.f)) / 2.f;
    std::vector<vec3> p = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                           {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
    for (vec3& v : p) v = glm::normalize(v);
    std::vector<std::uint32_t> idx = {0, 11, 5,  0, 5,  1, 0, 1, 7, 0, 7,  10, 0, 10, 11, 1, 5, 9, 5, 11,
                                      4, 11, 10, 2, 10, 7, 6, 7, 1, 8, 3,  9,  4, 3,  4,  2, 3, 2, 6, 3,
                                      6, 8,  3,  8, 9,  4, 9, 5, 2, 4, 11, 6,  2, 10, 8,  6, 7, 9, 8, 1};
    // Step: split every edge once per level, sharing midpoints through a map.
    for (int level = 0; level < levels; ++level) {
        std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> midpoints;
        auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
            const auto key = std::minmax(a, b);
            const auto it = midpoints.find(key);
            if (it != midpoints.end()) return it->second;
            p.push_back(glm::normalize(p[a] + p[b]));
            const std::uint32_t m = static_cast<std::uint32_t>(p.size() - 1);
            midpoints.emplace(key, m);
            return m;
        };
        std::vector<std::uint32_t> next;
        for (std::size_t i = 0; i < idx.size(); i += 3) {
            const std::uint32_t a = idx[i], b = idx[i + 1], c = idx[i + 2];
            const std::uint32_t ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
            next.insert(next.end(), {a, ab, ca, b, bc, ab, c, ca, bc, ab, bc, ca});
        }
        idx = std::move(next);
    }
    Geometry g;
    g.material = material;
    g.indices = std::move(idx);
    for (const vec3& v : p) {
        g.positions.push_back(radius * v);
        g.normals.push_back(v);
        g.uv0.emplace_back(0.5f + std::atan2(v.z, v.x) / (2.f * kPi), std::acos(glm::clamp(v.y, -1.f, 1.f)) / kPi);
    }
    return g;
}

Geometry makeGrid(float size, int n, MaterialId material) {
    Geometry g;
    g.material = material;
    const std::size_t vertices = static_cast<std::size_t>(n + 1) * static_cast<std::size_t>(n + 1);
    g.positions.reserve(vertices);
    g.normals.reserve(vertices);
    g.uv0.reserve(vertices);
    g.indices.reserve(6 * static_cast<std::size_t>(n) * static_cast<std::size_t>(n));
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) {
            const vec2 uv(static_cast<float>(i) / n, static_cast<float>(j) / n);
            g.positions.emplace_back((uv.x - 0.5f) * size, 0.f, (uv.y - 0.5f) * size);
            g.normals.emplace_back(0.f, 1.f, 0.f);
            g.uv0.push_back(uv);
        }
    const auto at = [n](int i, int j) { return static_cast<std::uint32_t>(j * (n + 1) + i); };
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
            g.indices.insert(g.indices.end(),
                             {at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i, j), at(i + 1, j + 1), at(i + 1, j)});
    return g;
}

Geometry makeQuad(float width, float height, MaterialId material) {
    Geometry g;
    g.material = material;
    const vec2 corners[4] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    for (const vec2& c : corners) {
        g.positions.emplace_back((c.x - 0.5f) * width, (c.y - 0.5f) * height, 0.f);
        g.normals.emplace_back(0.f, 0.f, 1.f);
        g.uv0.emplace_back(c.x, 1.f - c.y);
    }
    g.indices = {0, 1, 2, 0, 2, 3};
    return g;
}

Geometry makeLathe(const std::vector<vec2>& profile, int segments, MaterialId material) {
    Geometry g;
    g.material = material;
    const auto at = [segments](std::size_t ring, int s) {
        return static_cast<std::uint32_t>(ring * static_cast<std::size_t>(segments + 1) + static_cast<std::size_t>(s));
    };
    // Step: one ring of segments + 1 vertices per profile point (the seam is
    // duplicated so u runs 0..1).
    for (std::size_t ring = 0; ring < profile.size(); ++ring)
        for (int s = 0; s <= segments; ++s) {
            const float phi = 2.f * kPi * static_cast<float>(s) / static_cast<float>(segments);
            g.positions.emplace_back(profile[ring].x * std::cos(phi), profile[ring].y,
                                     -profile[ring].x * std::sin(phi));
            g.uv0.emplace_back(
                static_cast<float>(s) / static_cast<float>(segments),
                static_cast<float>(ring) / static_cast<float>(std::max<std::size_t>(profile.size() - 1, 1)));
        }
    // Step: quads between consecutive rings, counter-clockwise seen from outside.
    for (std::size_t ring = 0; ring + 1 < profile.size(); ++ring) {
        const bool lowerPoint = profile[ring].x == 0.f, upperPoint = profile[ring + 1].x == 0.f;
        if (lowerPoint && upperPoint) continue;
        for (int s = 0; s < segments; ++s) {
            const std::uint32_t a = at(ring, s), b = at(ring, s + 1), c = at(ring + 1, s + 1), d = at(ring + 1, s);
            if (!lowerPoint) g.indices.insert(g.indices.end(), {a, b, c});
            if (!upperPoint) g.indices.insert(g.indices.end(), {a, c, d});
        }
    }
    // Step: normals. Copies of one point (the seam, a zero-radius ring) share
    // the average of their normals, so displacing along them opens no crack.
    g.normals = generateVertexNormals(g.positions, g.indices);
    for (std::size_t ring = 0; ring < profile.size(); ++ring) {
        const int last = profile[ring].x == 0.f ? segments : 0;  // copies: 0..last and segments
        vec3 sum(0.f);
        for (int s = 0; s <= last; ++s) sum += g.normals[at(ring, s)];
        if (last != segments) sum += g.normals[at(ring, segments)];
        const vec3 shared = glm::dot(sum, sum) > 0.f ? glm::normalize(sum) : vec3(0.f, 1.f, 0.f);
        for (int s = 0; s <= last; ++s) g.normals[at(ring, s)] = shared;
        g.normals[at(ring, segments)] = shared;
    }
    return g;
}

MeshAsset makeMesh(std::string name, Geometry g) {
    MeshAsset m;
    m.name = std::move(name);
    m.geometries.push_back(std::move(g));
    return m;
}

}  // namespace rtlab::ecs::load
