// Scalable builtin scenes for RT-hardware and traversal-scheduling studies:
//   terrain?triangles=N   a displaced height field of about N unique triangles;
//   forest?instances=M    M instances of four plant/rock meshes on a terrain
//                         (two-level BVH, many instanced triangles);
//   hairball?triangles=N  N triangles of short, thin, curly strands filling a
//                         ball (the look of the archive's Hairball);
//   slivers?triangles=N   N long thin randomly oriented triangles in a sphere
//                         (heavy box overlap, the classic BVH worst case).
// Every random choice is a pure function of (seed, index) through the
// stateless hash in rtlab/core/rng.hpp, so a scene depends only on its
// parameters; per-element work runs in parallel and writes its own slots.
#include "builtin_common.hpp"

#include <rtlab/core/parallel.hpp>
#include <rtlab/core/rng.hpp>
#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>

namespace rtlab::ecs::load::builtin {
namespace {

// Hash streams (SampleKey::bounce) so that the scenes' random numbers do not
// reuse each other's.
enum Stream : std::uint32_t { kTerrainNoise = 1, kShapeNoise, kInstances, kHairs, kStrands };

// Uniform [0, 1) for element `index` of a stream; `dimension` picks which number.
float uniform(std::uint32_t seed, Stream stream, std::uint32_t index, std::uint32_t dimension) {
    return sampleUniform(SampleKey{index, 0, 0, stream, seed}, dimension);
}

float lattice(std::uint32_t seed, Stream stream, std::uint32_t octave, int x, int y, int z) {
    return sampleUniform(SampleKey{static_cast<std::uint32_t>(x), static_cast<std::uint32_t>(y),
                                   static_cast<std::uint32_t>(z), stream, seed},
                         octave);
}

float smooth(float t) { return t * t * (3.f - 2.f * t); }

// Value noise in [0, 1): smoothly interpolated hashed lattice values. The 2D
// version is the 3D one's y = 0 slice without the four lookups it would not use.
float valueNoise2(const vec2& p, std::uint32_t seed, Stream stream, std::uint32_t octave) {
    const vec2 f = glm::floor(p);
    const int x = static_cast<int>(f.x), z = static_cast<int>(f.y);
    const vec2 w(smooth(p.x - f.x), smooth(p.y - f.y));
    const auto at = [&](int dx, int dz) { return lattice(seed, stream, octave, x + dx, 0, z + dz); };
    return glm::mix(glm::mix(at(0, 0), at(1, 0), w.x), glm::mix(at(0, 1), at(1, 1), w.x), w.y);
}

float valueNoise3(const vec3& p, std::uint32_t seed, Stream stream, std::uint32_t octave) {
    const vec3 f = glm::floor(p);
    const int x = static_cast<int>(f.x), y = static_cast<int>(f.y), z = static_cast<int>(f.z);
    const vec3 w(smooth(p.x - f.x), smooth(p.y - f.y), smooth(p.z - f.z));
    const auto at = [&](int dx, int dy, int dz) { return lattice(seed, stream, octave, x + dx, y + dy, z + dz); };
    const auto plane = [&](int dy) {
        return glm::mix(glm::mix(at(0, dy, 0), at(1, dy, 0), w.x), glm::mix(at(0, dy, 1), at(1, dy, 1), w.x), w.z);
    };
    return glm::mix(plane(0), plane(1), w.y);
}

// Fractal sum of `octaves` noise layers, each twice the frequency and half
// the amplitude of the previous one, in [-1, 1].
template <class P, class Noise>
float fractalNoise(P p, int octaves, Noise noise) {
    float sum = 0.f, amplitude = 1.f, total = 0.f;
    for (int o = 0; o < octaves; ++o) {
        sum += amplitude * (2.f * noise(p, static_cast<std::uint32_t>(o)) - 1.f);
        total += amplitude;
        amplitude *= 0.5f;
        p *= 2.f;
    }
    return sum / total;
}

// A height field: fractal value noise sampled on makeGrid's vertices. The
// noise does not depend on the grid resolution, so every triangle count
// tessellates the same landscape.
struct HeightField {
    float side;        // the square's side (world units), centred at the origin
    int quads;         // per side
    float amplitude;   // world units
    float wavelength;  // of the coarsest octave
    std::uint32_t seed;
    Geometry grid;

    float noiseHeight(float x, float z) const {
        return amplitude * fractalNoise(vec2(x, z) / wavelength, 8, [&](const vec2& p, std::uint32_t octave) {
                   return valueNoise2(p, seed, kTerrainNoise, octave);
               });
    }

    void build(MaterialId material) {
        grid = makeGrid(side, quads, material);
        const int n1 = quads + 1;
        // Step: heights, one grid row per task.
        parallelForEach(static_cast<std::size_t>(n1), [&](std::size_t j) {
            for (std::size_t v = j * n1; v < (j + 1) * n1; ++v)
                grid.positions[v].y = noiseHeight(grid.positions[v].x, grid.positions[v].z);
        });
        // Step: normals from central differences (one-sided at the border).
        parallelForEach(static_cast<std::size_t>(n1), [&](std::size_t j) {
            for (int i = 0; i < n1; ++i) {
                const vec3 dx = vertex(std::min(i + 1, quads), static_cast<int>(j)) -
                                vertex(std::max(i - 1, 0), static_cast<int>(j));
                const vec3 dz = vertex(i, std::min(static_cast<int>(j) + 1, quads)) -
                                vertex(i, std::max(static_cast<int>(j) - 1, 0));
                grid.normals[j * n1 + i] = glm::normalize(glm::cross(dz, dx));
            }
        });
    }

    const vec3& vertex(int i, int j) const { return grid.positions[static_cast<std::size_t>(j) * (quads + 1) + i]; }

    // Height of the triangulated surface (not of the noise) at (x, z), so
    // that objects placed on it neither float nor sink between vertices.
    float surfaceHeight(float x, float z) const {
        const float fx = glm::clamp((x / side + 0.5f) * quads, 0.f, static_cast<float>(quads));
        const float fz = glm::clamp((z / side + 0.5f) * quads, 0.f, static_cast<float>(quads));
        const int i = std::min(static_cast<int>(fx), quads - 1), j = std::min(static_cast<int>(fz), quads - 1);
        const float u = fx - i, v = fz - j;
        const float h00 = vertex(i, j).y, h10 = vertex(i + 1, j).y, h01 = vertex(i, j + 1).y,
                    h11 = vertex(i + 1, j + 1).y;
        // makeGrid splits each quad along its (i, j)-(i+1, j+1) diagonal.
        return v > u ? h00 + (h11 - h01) * u + (h01 - h00) * v : h00 + (h10 - h00) * u + (h11 - h10) * v;
    }
};

// Moves every vertex along its normal by `amount` x fractal noise of its
// position (shared vertices move together: no cracks), then recomputes the
// normals.
void displace(Geometry& g, float amount, float frequency, std::uint32_t seed) {
    for (std::size_t v = 0; v < g.positions.size(); ++v)
        g.positions[v] +=
            g.normals[v] * amount * fractalNoise(g.positions[v] * frequency, 4, [&](const vec3& p, std::uint32_t o) {
                return valueNoise3(p, seed, kShapeNoise, o);
            });
    g.normals = generateVertexNormals(g.positions, g.indices);
}

void transform(Geometry& g, const vec3& scale, const vec3& offset) {
    for (vec3& p : g.positions) p = p * scale + offset;
    g.normals = generateVertexNormals(g.positions, g.indices);
}

Light sun(float intensity) { return Light{LightType::Directional, vec3(1.f, 0.95f, 0.85f), intensity}; }
const vec3 kSunDirection = glm::normalize(vec3(-0.4f, -1.f, -0.3f));

}  // namespace

void buildTerrain(World& world, const Parameters& p) {
    world.settings().name = "terrain";
    const std::uint32_t requested = p.at("triangles");
    // Step: the square grid whose 2 n^2 triangles are nearest the request.
    const int n = std::max(1, static_cast<int>(std::lround(std::sqrt(requested / 2.0))));
    HeightField field{100.f, n, 12.f, 40.f, p.at("seed"), {}};
    field.build(world.addMaterial(diffuse("terrain", vec3(0.36f, 0.38f, 0.26f))));
    const std::size_t triangles = field.grid.triangleCount();
    place(world, "terrain", world.addMesh(makeMesh("terrain", std::move(field.grid))), vec3(0.f));
    world.settings().generated = std::to_string(n) + " x " + std::to_string(n) + " quad height field, " +
                                 std::to_string(triangles) + " unique triangles (the square grid nearest " +
                                 std::to_string(requested) + ")";

    // Step: a sun and a large soft panel above the middle (area-light shadows).
    addLight(world, "sun", sun(3.f), vec3(0.f), kSunDirection);
    Light panel{LightType::Rect, vec3(0.9f, 0.95f, 1.f), 20.f};
    panel.size = vec2(20.f);
    addLight(world, "sky panel", panel, vec3(0.f, 60.f, 0.f));
    addCamera(world, vec3(0.f, 28.f, 62.f), vec3(0.f, 0.f, 0.f), 0.9f, 400.f);
}

void buildForest(World& world, const Parameters& p) {
    world.settings().name = "forest";
    const std::uint32_t instances = p.at("instances"), seed = p.at("seed");
    // Step: the ground grows with the instance count (about 64 m^2 per instance).
    const float side = std::max(64.f, 8.f * std::sqrt(static_cast<float>(instances)));
    HeightField field{side, 256, 8.f, 60.f, seed, {}};
    field.build(world.addMaterial(diffuse("forest floor", vec3(0.3f, 0.33f, 0.2f))));
    place(world, "ground", world.addMesh(makeMesh("ground", Geometry(field.grid))), vec3(0.f));

    // Step: four distinct meshes, each shaped by the seed.
    const MaterialId bark = world.addMaterial(diffuse("bark", vec3(0.3f, 0.2f, 0.12f)));
    const MaterialId needles = world.addMaterial(diffuse("needles", vec3(0.08f, 0.25f, 0.1f)));
    const MaterialId leaves = world.addMaterial(diffuse("leaves", vec3(0.2f, 0.42f, 0.1f)));
    const MaterialId stone = world.addMaterial(diffuse("rock", vec3(0.45f, 0.44f, 0.42f)));
    const auto trunk = [&](float radius, float height) {
        return makeLathe({{radius, -0.3f}, {0.7f * radius, height}, {0.f, height}}, 12, bark);
    };
    MeshAsset conifer = makeMesh("conifer", trunk(0.22f, 2.f));
    {
        // Four stacked cones as one zig-zag profile, each edge cut in four.
        const std::array<vec2, 9> corners = {vec2{0.f, 1.2f}, {2.2f, 1.2f}, {0.6f, 3.3f}, {1.8f, 3.1f}, {0.45f, 5.1f},
                                             {1.4f, 4.9f},    {0.3f, 6.6f}, {0.9f, 6.5f}, {0.f, 8.2f}};
        std::vector<vec2> profile{corners[0]};
        for (std::size_t c = 1; c < corners.size(); ++c)
            for (int k = 1; k <= 4; ++k) profile.push_back(glm::mix(corners[c - 1], corners[c], k / 4.f));
        Geometry crown = makeLathe(profile, 48, needles);
        displace(crown, 0.25f, 1.5f, seed ^ 0x11u);
        conifer.geometries.push_back(std::move(crown));
    }
    MeshAsset broadleaf = makeMesh("broadleaf tree", trunk(0.25f, 3.2f));
    {
        Geometry crown = makeIcosphere(1.f, 4, leaves);
        displace(crown, 0.3f, 2.f, seed ^ 0x22u);
        transform(crown, vec3(2.2f, 1.9f, 2.2f), vec3(0.f, 4.6f, 0.f));
        broadleaf.geometries.push_back(std::move(crown));
    }
    Geometry bushShape = makeIcosphere(1.f, 3, leaves);
    displace(bushShape, 0.4f, 2.5f, seed ^ 0x33u);
    transform(bushShape, vec3(0.9f, 0.6f, 0.9f), vec3(0.f, 0.4f, 0.f));
    Geometry rockShape = makeIcosphere(1.f, 3, stone);
    displace(rockShape, 0.35f, 1.2f, seed ^ 0x44u);
    transform(rockShape, vec3(1.2f, 0.7f, 1.f), vec3(0.f));
    struct Kind {
        const char* name;
        MeshId mesh;
        float share;  // of the instances (cumulative below)
        float sink;   // how far below the surface the mesh origin goes
    };
    const std::array<Kind, 4> kinds = {Kind{"conifer", world.addMesh(std::move(conifer)), 0.45f, 0.f},
                                       Kind{"broadleaf tree", world.addMesh(std::move(broadleaf)), 0.25f, 0.f},
                                       Kind{"bush", world.addMesh(makeMesh("bush", std::move(bushShape))), 0.2f, 0.1f},
                                       Kind{"rock", world.addMesh(makeMesh("rock", std::move(rockShape))), 0.1f, 0.3f}};

    // Step: instances at hashed positions on the ground, hashed kind, yaw and scale.
    std::array<std::size_t, 4> counts{};
    for (std::uint32_t i = 0; i < instances; ++i) {
        const float x = (uniform(seed, kInstances, i, 0) - 0.5f) * 0.98f * side;
        const float z = (uniform(seed, kInstances, i, 1) - 0.5f) * 0.98f * side;
        float pick = uniform(seed, kInstances, i, 2);
        std::size_t k = 0;
        while (k + 1 < kinds.size() && pick >= kinds[k].share) pick -= kinds[k++].share;
        const float yaw = 2.f * kPi * uniform(seed, kInstances, i, 3);
        const float scale = 0.7f + 0.6f * uniform(seed, kInstances, i, 4);
        place(world, kinds[k].name, kinds[k].mesh, vec3(x, field.surfaceHeight(x, z) - kinds[k].sink * scale, z),
              glm::angleAxis(yaw, vec3(0.f, 1.f, 0.f)), vec3(scale));
        ++counts[k];
    }
    char line[256];
    std::snprintf(line, sizeof line,
                  "%u instances (%zu conifers, %zu broadleaf trees, %zu bushes, %zu rocks) on a %.0f m ground of "
                  "256 x 256 quads",
                  instances, counts[0], counts[1], counts[2], counts[3], side);
    world.settings().generated = line;

    addLight(world, "sun", sun(3.f), vec3(0.f), kSunDirection);
    const float z = 0.45f * side, height = 10.f + 0.03f * side;
    addCamera(world, vec3(0.f, field.surfaceHeight(0.f, z) + height, z), vec3(0.f, field.surfaceHeight(0.f, 0.f), 0.f),
              0.9f, 3.f * side);
}

void buildSlivers(World& world, const Parameters& p) {
    world.settings().name = "slivers";
    const std::uint32_t count = p.at("triangles"), seed = p.at("seed");
    Material hairMaterial = diffuse("hair", vec3(0.6f, 0.45f, 0.3f));
    hairMaterial.doubleSided = true;
    Geometry g;
    g.material = world.addMaterial(hairMaterial);
    g.positions.resize(3 * static_cast<std::size_t>(count));
    g.normals.resize(g.positions.size());
    g.indices.resize(g.positions.size());
    // Step: each triangle a sliver of length 0.5..1 and base width 0.002 (1e-3
    // of the ball's diameter), centred within 0.5 of the origin so it stays
    // inside the unit ball, pointing anywhere. Blocks of 4096 per task.
    constexpr std::size_t kBlock = 4096;
    parallelForEach((count + kBlock - 1) / kBlock, [&](std::size_t block) {
        const std::size_t end = std::min<std::size_t>(count, (block + 1) * kBlock);
        for (std::size_t t = block * kBlock; t < end; ++t) {
            const auto u = [&](std::uint32_t d) { return uniform(seed, kHairs, static_cast<std::uint32_t>(t), d); };
            const auto unitVector = [](float a, float b) {
                const float z = 2.f * a - 1.f, r = std::sqrt(std::max(0.f, 1.f - z * z)), phi = 2.f * kPi * b;
                return vec3(r * std::cos(phi), r * std::sin(phi), z);
            };
            const vec3 centre = 0.5f * std::cbrt(u(0)) * unitVector(u(1), u(2));
            const vec3 along = unitVector(u(3), u(4));
            const vec3 across = glm::normalize(glm::cross(along, unitVector(u(5), u(6)) + 1e-3f * vec3(1.f, 0.f, 0.f)));
            const float length = 0.5f + 0.5f * u(7), width = 0.002f;
            const vec3 base = centre - 0.5f * length * along;
            const vec3 corners[3] = {base - 0.5f * width * across, base + 0.5f * width * across,
                                     centre + 0.5f * length * along};
            const vec3 normal = glm::normalize(glm::cross(corners[1] - corners[0], corners[2] - corners[0]));
            for (std::size_t c = 0; c < 3; ++c) {
                g.positions[3 * t + c] = corners[c];
                g.normals[3 * t + c] = normal;
                g.indices[3 * t + c] = static_cast<std::uint32_t>(3 * t + c);
            }
        }
    });
    place(world, "slivers", world.addMesh(makeMesh("slivers", std::move(g))), vec3(0.f));
    world.settings().generated =
        std::to_string(count) + " slivers (length 0.5 to 1, base width 0.002) in a ball of radius 1";

    addLight(world, "sun", sun(3.f), vec3(0.f), kSunDirection);
    Light point{LightType::Point, vec3(1.f, 0.9f, 0.8f), 8.f};
    addLight(world, "key light", point, vec3(2.f, 2.f, 2.5f));
    addCamera(world, vec3(0.f, 0.4f, 3.2f), vec3(0.f), 0.75f);
}

// Rotates `v` by `angle` about the unit axis `axis` (Rodrigues).
vec3 rotated(const vec3& v, const vec3& axis, float angle) {
    const float c = std::cos(angle), s = std::sin(angle);
    return c * v + s * glm::cross(axis, v) + (1.f - c) * glm::dot(axis, v) * axis;
}

void buildHairball(World& world, const Parameters& p) {
    world.settings().name = "hairball";
    const std::uint32_t count = p.at("triangles"), seed = p.at("seed");
    // Each strand is a ribbon of kSegments thin quads (two triangles each) along
    // a smooth curly curve; the last strand is cut short so that the mesh has
    // exactly `count` triangles and no unused vertex (a strip of t triangles
    // uses t + 2 vertices).
    constexpr std::uint32_t kSegments = 8, kTrianglesPerStrand = 2 * kSegments, kVerticesPerStrand = 2 * kSegments + 2;
    const std::uint32_t strands = (count + kTrianglesPerStrand - 1) / kTrianglesPerStrand;
    const std::uint32_t lastTriangles = count - (strands - 1) * kTrianglesPerStrand;
    const std::size_t vertexCount = std::size_t{strands - 1} * kVerticesPerStrand + lastTriangles + 2;
    Material hairMaterial = diffuse("hair", vec3(0.6f, 0.45f, 0.3f));
    hairMaterial.doubleSided = true;
    Geometry g;
    g.material = world.addMaterial(hairMaterial);
    g.positions.resize(vertexCount);
    g.normals.resize(vertexCount);
    g.indices.resize(3 * static_cast<std::size_t>(count));
    constexpr std::size_t kBlock = 1024;
    parallelForEach((strands + kBlock - 1) / kBlock, [&](std::size_t block) {
        const std::size_t end = std::min<std::size_t>(strands, (block + 1) * kBlock);
        for (std::size_t strand = block * kBlock; strand < end; ++strand) {
            const auto u = [&](std::uint32_t d) {
                return uniform(seed, kStrands, static_cast<std::uint32_t>(strand), d);
            };
            const auto unitVector = [](float a, float b) {
                const float z = 2.f * a - 1.f, r = std::sqrt(std::max(0.f, 1.f - z * z)), phi = 2.f * kPi * b;
                return vec3(r * std::cos(phi), r * std::sin(phi), z);
            };
            // Step: a root within 0.8 of the centre, a heading, and a curl axis
            // across it (the ribbon's width direction stays along that axis).
            vec3 position = 0.8f * std::cbrt(u(0)) * unitVector(u(1), u(2));
            vec3 heading = unitVector(u(3), u(4));
            vec3 axis = glm::cross(heading, unitVector(u(5), u(6)));
            axis = glm::length(axis) > 1e-3f
                       ? glm::normalize(axis)
                       : glm::normalize(glm::cross(heading, vec3(0.f, 0.f, 1.f)) + vec3(1e-3f, 0.f, 0.f));
            axis = glm::normalize(axis - glm::dot(axis, heading) * heading);
            // Step: strand length 0.25..0.45, curl 0.45..1 radian a segment (a
            // loop in 6 to 14 segments), a slow random twist of the curl axis,
            // width 0.004 at the root tapering to 0.0012 at the tip.
            const float segmentLength = (0.25f + 0.2f * u(7)) / kSegments, curl = 0.45f + 0.55f * u(8);
            const float rootWidth = 0.004f;
            const std::size_t firstVertex = strand * kVerticesPerStrand, firstTriangle = strand * kTrianglesPerStrand;
            for (std::uint32_t k = 0; k <= kSegments; ++k) {
                const float halfWidth = 0.5f * rootWidth * (1.f - 0.7f * static_cast<float>(k) / kSegments);
                const vec3 normal = glm::normalize(glm::cross(axis, heading));
                for (std::uint32_t side = 0; side < 2; ++side) {
                    const std::size_t v = firstVertex + 2 * k + side;
                    if (v >= vertexCount) break;
                    g.positions[v] = position + (side == 0 ? -halfWidth : halfWidth) * axis;
                    g.normals[v] = normal;
                }
                position += segmentLength * heading;
                heading = glm::normalize(rotated(heading, axis, curl));
                const float twist = 0.8f * (u(9 + k) - 0.5f);
                axis = glm::normalize(rotated(axis, heading, twist));
                axis = glm::normalize(axis - glm::dot(axis, heading) * heading);
            }
            // Step: quad k joins vertices 2k, 2k+1 with 2k+2, 2k+3.
            for (std::uint32_t t = 0; t < kTrianglesPerStrand && firstTriangle + t < count; ++t) {
                const auto v0 = static_cast<std::uint32_t>(firstVertex + 2 * (t / 2));
                const std::array<std::uint32_t, 3> corners = t % 2 == 0
                                                                 ? std::array<std::uint32_t, 3>{v0, v0 + 1, v0 + 2}
                                                                 : std::array<std::uint32_t, 3>{v0 + 1, v0 + 3, v0 + 2};
                for (std::size_t c = 0; c < 3; ++c) g.indices[3 * (firstTriangle + t) + c] = corners[c];
            }
        }
    });
    place(world, "hairball", world.addMesh(makeMesh("hairball", std::move(g))), vec3(0.f));
    world.settings().generated = std::to_string(count) + " triangles in " + std::to_string(strands) +
                                 " curly strands (8 quads each, length 0.25 to 0.45, width 0.004 tapering to "
                                 "0.0012) in a ball of radius about 1.2";

    addLight(world, "sun", sun(3.f), vec3(0.f), kSunDirection);
    Light point{LightType::Point, vec3(1.f, 0.9f, 0.8f), 8.f};
    addLight(world, "key light", point, vec3(2.f, 2.f, 2.5f));
    addCamera(world, vec3(0.f, 0.4f, 2.9f), vec3(0.f), 0.75f);
}

}  // namespace rtlab::ecs::load::builtin
