// The scalable builtin scenes (terrain, forest, hairball, slivers) at small sizes:
// parameters, triangle counts, placement, determinism. Large sizes are for
// the benchmarks (perf/scalable_scenes.cpp).
#include <rtlab/core/error.hpp>
#include <rtlab/core/parallel.hpp>
#include <rtlab/core/rng.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <map>
#include <string>

using namespace rtlab;
using namespace rtlab::ecs;

namespace {

std::string loadError(const std::string& source) {
    World world;
    try {
        load::loadScene(world, source);
    } catch (const InputError& e) {
        return e.what();
    }
    return "(no error)";
}

// Hash of every mesh's positions, indices and materials and every instance's
// transform, in entity order: equal hashes mean equal geometry.
std::uint32_t geometryHash(const World& world) {
    std::uint32_t h = 0;
    const auto mixBits = [&h](const void* data, std::size_t bytes) {
        for (std::size_t i = 0; i + 4 <= bytes; i += 4) {
            std::uint32_t word;
            std::memcpy(&word, static_cast<const char*>(data) + i, 4);
            h = pcgHash(h ^ word);
        }
    };
    for (const MeshAsset& m : world.meshes())
        for (const Geometry& g : m.geometries) {
            mixBits(g.positions.data(), g.positions.size() * sizeof(vec3));
            mixBits(g.normals.data(), g.normals.size() * sizeof(vec3));
            mixBits(g.indices.data(), g.indices.size() * sizeof(std::uint32_t));
            mixBits(&g.material, sizeof g.material);
        }
    world.each<MeshInstance>([&](Entity e, const MeshInstance& inst) {
        mixBits(&inst.mesh, sizeof inst.mesh);
        const mat4 m = world.computeInstanceWorldFromObject(e);
        mixBits(&m, sizeof m);
    });
    return h;
}

std::uint32_t loadedHash(const std::string& source, int threads = 0) {
    const ThreadLimit limit(threads);
    World world;
    load::loadScene(world, source);
    return geometryHash(world);
}

std::size_t instancedTriangles(const World& world) {
    std::size_t n = 0;
    world.each<MeshInstance>([&](Entity, const MeshInstance& inst) { n += world.mesh(inst.mesh).triangleCount(); });
    return n;
}

int countLights(const World& world, LightType type) {
    int n = 0;
    world.each<Light>([&](Entity, const Light& l) { n += l.type == type; });
    return n;
}

}  // namespace

TEST(ScalableScenes, ParameterErrorsNameTheParameterAndWhatIsAccepted) {
    EXPECT_EQ(loadError("builtin:terrain?size=3"),
              "builtin:terrain?size=3: unknown parameter 'size' (accepted: triangles, seed)");
    EXPECT_EQ(loadError("builtin:forest?triangles=3000"),
              "builtin:forest?triangles=3000: unknown parameter 'triangles' (accepted: instances, seed)");
    EXPECT_EQ(loadError("builtin:showcase?seed=2"),
              "builtin:showcase?seed=2: unknown parameter 'seed' (builtin:showcase takes no parameters)");
    EXPECT_EQ(loadError("builtin:hairball?triangles=12.5"),
              "builtin:hairball?triangles=12.5: parameter 'triangles' has value '12.5', expected an integer from "
              "1000 to 10000000");
    EXPECT_EQ(loadError("builtin:hairball?triangles=1e8"),
              "builtin:hairball?triangles=1e8: parameter 'triangles' is 100000000, out of range (1000 to 10000000)");
    EXPECT_EQ(loadError("builtin:terrain?triangles="),
              "builtin:terrain?triangles=: parameter 'triangles' has value '', expected an integer from 1000 to "
              "10000000");
    EXPECT_EQ(loadError("builtin:terrain?"),
              "builtin:terrain?: expected key=value, got '' (accepted: triangles, seed)");
    EXPECT_EQ(loadError("builtin:terrain?seed=1&&triangles=2000"),
              "builtin:terrain?seed=1&&triangles=2000: expected key=value, got '' (accepted: triangles, seed)");
    EXPECT_EQ(loadError("builtin:forest?instances=1000001"),
              "builtin:forest?instances=1000001: parameter 'instances' is 1000001, out of range (1 to 1000000)");
    EXPECT_EQ(loadError("builtin:forest?seed=4294967296"),
              "builtin:forest?seed=4294967296: parameter 'seed' has value '4294967296', expected an integer from 0 "
              "to 4294967295");
    EXPECT_EQ(loadError("builtin:mountains"),
              "builtin:mountains: unknown builtin scene (available: showcase, cornell, terrain, forest, hairball, "
              "slivers)");
    EXPECT_EQ(loadError("builtin:forest?seed=4294967295&instances=1"), "(no error)");
}

TEST(ScalableScenes, DefaultsAreFilledInAndRecorded) {
    World world;
    load::loadScene(world, "builtin:hairball?seed=5");
    using Entry = std::pair<std::string, std::uint32_t>;
    const std::vector<Entry> expected = {{"triangles", 100000u}, {"seed", 5u}};
    EXPECT_EQ(world.settings().parameters, expected);
    EXPECT_EQ(world.mesh(0).triangleCount(), 100000u);
    World showcase;
    load::loadScene(showcase, "builtin:showcase");
    EXPECT_TRUE(showcase.settings().parameters.empty());
    EXPECT_TRUE(showcase.settings().generated.empty());
}

TEST(ScalableScenes, TerrainPicksTheNearestSquareGridAndHasLightsAndACamera) {
    for (const auto& [requested, built] : {std::pair{1000u, 968u}, {1250u, 1250u}, {5000u, 5000u}, {9000u, 8978u}}) {
        World world;
        load::loadScene(world, "builtin:terrain?triangles=" + std::to_string(requested));
        ASSERT_EQ(world.meshes().size(), 1u);
        EXPECT_EQ(world.mesh(0).triangleCount(), built) << requested;
        EXPECT_EQ(load::degenerateTriangleCount(world.mesh(0)), 0u);
        EXPECT_NE(world.settings().generated.find(std::to_string(built) + " unique triangles"), std::string::npos)
            << world.settings().generated;
        EXPECT_EQ(countLights(world, LightType::Rect), 1);
        EXPECT_EQ(countLights(world, LightType::Directional), 1);
        EXPECT_TRUE(world.alive(world.activeCamera()));
        EXPECT_EQ(world.get<Name>(world.activeCamera())->value, "camera");  // the scene's, not the default
    }
}

TEST(ScalableScenes, TerrainResolutionDoesNotChangeTheLandscape) {
    // 25 and 50 quads per side: every coarse vertex is a fine vertex at the
    // same height (the noise does not depend on the resolution).
    World coarse, fine;
    load::loadScene(coarse, "builtin:terrain?triangles=1250&seed=9");
    load::loadScene(fine, "builtin:terrain?triangles=5000&seed=9");
    const Geometry& c = coarse.mesh(0).geometries[0];
    const Geometry& f = fine.mesh(0).geometries[0];
    ASSERT_EQ(c.positions.size(), 26u * 26u);
    ASSERT_EQ(f.positions.size(), 51u * 51u);
    float lo = 1e9f, hi = -1e9f;
    for (int j = 0; j <= 25; ++j)
        for (int i = 0; i <= 25; ++i) {
            const vec3& p = c.positions[j * 26 + i];
            EXPECT_EQ(p, f.positions[(2 * j) * 51 + 2 * i]) << i << " " << j;
            lo = std::min(lo, p.y);
            hi = std::max(hi, p.y);
        }
    EXPECT_GT(hi - lo, 2.f) << "displaced, not flat";
    for (const vec3& n : f.normals) EXPECT_NEAR(glm::length(n), 1.f, 1e-5f);
}

TEST(ScalableScenes, ForestInstancesStandOnTheGround) {
    World world;
    load::loadScene(world, "builtin:forest?instances=200&seed=4");
    ASSERT_EQ(world.meshes().size(), 5u);  // ground + conifer, broadleaf tree, bush, rock
    EXPECT_EQ(world.count<MeshInstance>(), 201u);
    std::size_t unique = 0;
    for (const MeshAsset& m : world.meshes()) {
        unique += m.triangleCount();
        EXPECT_EQ(load::degenerateTriangleCount(m), 0u) << m.name;
    }
    EXPECT_GT(instancedTriangles(world), unique);
    // The tree is a cone tree of a few thousand triangles; bush and rock are
    // subdivided icospheres (20 x 4^3).
    EXPECT_GT(world.mesh(1).triangleCount(), 2000u);
    EXPECT_LT(world.mesh(1).triangleCount(), 6000u);
    EXPECT_EQ(world.mesh(3).triangleCount(), 1280u);
    EXPECT_EQ(world.mesh(4).triangleCount(), 1280u);
    // Each tree's origin lies on the ground triangle beneath it, found here by
    // brute force over the ground mesh (the loader interpolates its grid).
    const Geometry& ground = world.mesh(0).geometries[0];
    int trees = 0;
    std::map<MeshId, int> perMesh;
    world.each<MeshInstance>([&](Entity e, const MeshInstance& inst) {
        ++perMesh[inst.mesh];
        const std::string& name = world.get<Name>(e)->value;
        if (name != "conifer" && name != "broadleaf tree") return;
        const vec3 o = world.get<LocalTransform>(e)->translation;
        bool found = false;
        for (std::size_t t = 0; t < ground.indices.size() && !found; t += 3) {
            const vec3 a = ground.positions[ground.indices[t]], b = ground.positions[ground.indices[t + 1]],
                       c = ground.positions[ground.indices[t + 2]];
            // Barycentric weights of o's XZ projection (u for a, v for b, w for c).
            const float wa = (b.x - o.x) * (c.z - o.z) - (c.x - o.x) * (b.z - o.z);
            const float wb = (c.x - o.x) * (a.z - o.z) - (a.x - o.x) * (c.z - o.z);
            const float total = (b.x - a.x) * (c.z - a.z) - (c.x - a.x) * (b.z - a.z);
            const float u = wa / total, v = wb / total, w = 1.f - u - v;
            if (u < -1e-5f || v < -1e-5f || w < -1e-5f) continue;
            found = true;
            EXPECT_NEAR(o.y, u * a.y + v * b.y + w * c.y, 1e-3f) << name;
        }
        EXPECT_TRUE(found) << name << " outside the ground";
        ++trees;
    });
    EXPECT_GT(trees, 100);  // 70% of 200 are trees
    EXPECT_EQ(perMesh.size(), 5u) << "every mesh is used";
    EXPECT_EQ(countLights(world, LightType::Directional), 1);
    EXPECT_EQ(world.get<Name>(world.activeCamera())->value, "camera");
}

TEST(ScalableScenes, HairballIsExactlyNTrianglesOfThinCurlyStrandsInABall) {
    for (const std::uint32_t requested : {1000u, 1001u, 3000u, 4096u}) {
        World world;
        load::loadScene(world, "builtin:hairball?seed=2&triangles=" + std::to_string(requested));
        ASSERT_EQ(world.meshes().size(), 1u);
        const Geometry& g = world.mesh(0).geometries[0];
        ASSERT_EQ(g.triangleCount(), requested);
        EXPECT_TRUE(world.materials().at(g.material).doubleSided);
        std::vector<bool> used(g.positions.size(), false);
        for (const std::uint32_t i : g.indices) {
            ASSERT_LT(i, g.positions.size());
            used[i] = true;
        }
        EXPECT_EQ(std::count(used.begin(), used.end(), false), 0) << requested << ": every vertex is used";
        for (const vec3& p : g.positions) EXPECT_LE(glm::length(p), 1.3f);
        for (const vec3& n : g.normals) EXPECT_NEAR(glm::length(n), 1.f, 1e-4f);
        EXPECT_EQ(load::degenerateTriangleCount(world.mesh(0)), 0u);
        // Thin: every quad's first triangle spans the ribbon's width (at most
        // 0.004) across and one segment (0.03 to 0.06) along.
        for (std::size_t t = 0; t < g.indices.size(); t += 6) {
            const vec3 a = g.positions[g.indices[t]], b = g.positions[g.indices[t + 1]],
                       c = g.positions[g.indices[t + 2]];
            EXPECT_LE(glm::distance(a, b), 0.004f + 1e-5f);
            EXPECT_GE(glm::distance(a, c), 0.03f);
            EXPECT_LE(glm::distance(a, c), 0.06f);
        }
    }
    // Curly: a whole strand (18 vertices, 9 along its centre line) is far
    // shorter root to tip than along its curve; strands point anywhere.
    World world;
    load::loadScene(world, "builtin:hairball?triangles=16000&seed=3");
    const Geometry& g = world.mesh(0).geometries[0];
    ASSERT_EQ(g.positions.size(), 1000u * 18u);
    float chordOverArc = 0.f;
    vec3 meanDirection(0.f);
    for (std::size_t strand = 0; strand < 1000; ++strand) {
        const auto centre = [&](std::size_t k) {
            return 0.5f * (g.positions[18 * strand + 2 * k] + g.positions[18 * strand + 2 * k + 1]);
        };
        float arc = 0.f;
        for (std::size_t k = 0; k < 8; ++k) arc += glm::distance(centre(k), centre(k + 1));
        EXPECT_GE(arc, 0.25f - 1e-3f);
        EXPECT_LE(arc, 0.45f + 1e-3f);
        chordOverArc += glm::distance(centre(0), centre(8)) / arc / 1000.f;
        meanDirection += glm::normalize(centre(1) - centre(0)) / 1000.f;
    }
    EXPECT_LT(chordOverArc, 0.8f);
    EXPECT_GT(chordOverArc, 0.1f);
    EXPECT_LT(glm::length(meanDirection), 0.1f);
}

TEST(ScalableScenes, SliversAreThinSliversInsideTheUnitBall) {
    World world;
    load::loadScene(world, "builtin:slivers?triangles=3000&seed=2");
    ASSERT_EQ(world.meshes().size(), 1u);
    const Geometry& g = world.mesh(0).geometries[0];
    ASSERT_EQ(g.triangleCount(), 3000u);
    EXPECT_TRUE(world.materials().at(g.material).doubleSided);
    vec3 meanDirection(0.f);
    for (std::size_t t = 0; t < g.indices.size(); t += 3) {
        const vec3 a = g.positions[g.indices[t]], b = g.positions[g.indices[t + 1]], c = g.positions[g.indices[t + 2]];
        for (const vec3& p : {a, b, c}) EXPECT_LE(glm::length(p), 1.f + 1e-3f);
        EXPECT_NEAR(glm::distance(a, b), 0.002f, 1e-5f);
        const float length = glm::distance(0.5f * (a + b), c);
        EXPECT_GE(length, 0.5f - 1e-4f);
        EXPECT_LE(length, 1.f + 1e-4f);
        meanDirection += glm::normalize(c - a);
    }
    // Random orientation: the directions nearly cancel out.
    EXPECT_LT(glm::length(meanDirection) / 3000.f, 0.1f);
    EXPECT_EQ(load::degenerateTriangleCount(world.mesh(0)), 0u);
}

TEST(ScalableScenes, SameSeedSameGeometryOnAnyThreadCountOtherSeedOther) {
    for (const std::string scene : {"builtin:terrain?triangles=20000", "builtin:forest?instances=100",
                                    "builtin:hairball?triangles=20000", "builtin:slivers?triangles=20000"}) {
        const std::uint32_t h = loadedHash(scene + "&seed=11", 1);
        EXPECT_EQ(h, loadedHash(scene + "&seed=11", 2)) << scene;
        EXPECT_EQ(h, loadedHash("builtin:" + scene.substr(8, scene.find('?') - 8) + "?seed=11&" +
                                scene.substr(scene.find('?') + 1)))
            << scene << ": parameter order does not matter";
        EXPECT_NE(h, loadedHash(scene + "&seed=12")) << scene;
        EXPECT_EQ(loadedHash(scene), loadedHash(scene + "&seed=0")) << scene << ": the default seed is 0";
    }
}
