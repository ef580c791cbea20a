// The programmable side through the shared step: procedural AABBs in the
// BLAS reaching the intersection callback, any-hit verdicts (ignore, end
// search), skip flags, and the timed model agreeing with the functional
// traversal under a non-trivial side.
#include "rtcore_timing_helpers.hpp"

#include <gtest/gtest.h>

using namespace rtlab;
using namespace rtlab::rtcore_sim;
using namespace rtlab::rtcore_sim::test_support;

namespace {

// Procedural spheres inscribed in their boxes (analytic hit), recording calls.
class SphereSide final : public ProgrammableSide {
public:
    SphereSide(const ModelScene& model, const ecs::SceneSnapshot& snapshot, const std::vector<SimRay>& rays)
        : model_(model), snapshot_(snapshot), rays_(rays) {}

    CandidateVerdict triangle(std::uint32_t, const TriangleCandidate&) override {
        ++triangleCalls;
        return {};
    }
    ProceduralVerdict procedural(std::uint32_t rayIndex, const ProceduralCandidate& c) override {
        ++proceduralCalls;
        const ModelInstance& inst = model_.instances()[c.instance];
        const Aabb& box = (*snapshot_.meshes)[inst.mesh].geometries[c.geometry].proceduralBoxes[c.primitive];
        const ModelRay& r = rays_[rayIndex].ray;
        const glm::dvec3 o = glm::dvec3(inst.objectFromWorld * glm::dvec4(glm::dvec3(r.origin), 1.0));
        const glm::dvec3 d = glm::dmat3(inst.objectFromWorld) * glm::dvec3(r.direction);
        const glm::dvec3 centre = glm::dvec3(box.center());
        const double radius = 0.5 * double(box.extent().x);
        const glm::dvec3 oc = o - centre;
        const double a = glm::dot(d, d), b = glm::dot(oc, d), cc = glm::dot(oc, oc) - radius * radius;
        const double disc = b * b - a * cc;
        ProceduralVerdict v;
        v.shaderRan = true;
        if (disc < 0.0) return v;
        const float t = static_cast<float>((-b - std::sqrt(disc)) / a);
        if (t > r.tMin && t < c.tClosest) {
            v.commit = true;
            v.t = t;
        }
        return v;
    }

    std::uint32_t triangleCalls = 0, proceduralCalls = 0;

private:
    const ModelScene& model_;
    const ecs::SceneSnapshot& snapshot_;
    const std::vector<SimRay>& rays_;
};

// Any-hit logic: ignores (does not commit) primitive `ignored`; ends the
// search at the first commit when `endSearch` (DXR AcceptHitAndEndSearch).
class FilterSide final : public ProgrammableSide {
public:
    FilterSide(std::uint32_t ignored, bool endSearch) : ignored_(ignored), endSearch_(endSearch) {}
    CandidateVerdict triangle(std::uint32_t, const TriangleCandidate& c) override {
        CandidateVerdict v;
        v.shaderRan = true;
        v.commit = c.primitive != ignored_;
        v.endSearch = endSearch_ && v.commit;
        return v;
    }
    ProceduralVerdict procedural(std::uint32_t, const ProceduralCandidate&) override { return {}; }

private:
    std::uint32_t ignored_;
    bool endSearch_;
};

}  // namespace

TEST(RtCoreProgrammable, ProceduralBoxReachesTheIntersectionCallback) {
    // One instance of a mesh with a procedural box [-1, 1]^3 at z = -5 and a
    // triangle geometry behind it: the box (geometry 0) and the triangle
    // (geometry 1) share one BLAS leaf (the default leaf size is 4).
    RtCoreConfig config;
    config.bvh.sahTraversalCost = 100.f;  // the builder keeps both primitives in one leaf
    MicroScene scene;
    scene.world.addMaterial({});
    ecs::MeshAsset mesh;
    mesh.name = "mixed";
    ecs::Geometry box;
    box.proceduralBoxes = {Aabb{vec3(-1.f), vec3(1.f)}};
    mesh.geometries.push_back(box);
    mesh.geometries.push_back(oneTriangleGeometry(vec3(-2.f, -2.f, -3.f), vec3(2.f, -2.f, -3.f), vec3(0.f, 2.f, -3.f)));
    const ecs::MeshId id = scene.world.addMesh(std::move(mesh));
    const ecs::Entity e = scene.world.create("mixed");
    scene.world.emplace(e, ecs::LocalTransform{vec3(0.f, 0.f, -5.f)});
    scene.world.emplace(e, ecs::MeshInstance{id});
    scene.build(config.bvh);
    const Blas& blas = *scene.model->blas(id);
    ASSERT_EQ(blas.bvh.refs.size(), 2u);
    ASSERT_TRUE(blas.bvh.root.isLeaf());
    EXPECT_TRUE(blas.isProcedural(PrimitiveRef{0, 0}));
    EXPECT_FALSE(blas.isProcedural(PrimitiveRef{1, 0}));

    const std::vector<SimRay> rays{simRay(makeModelRay(vec3(0.f, 0.f, 1.f), vec3(0.f, 0.f, -1.f)))};
    // Functional: the sphere's front at z = -4 (t = 5) wins over the triangle at z = -8 (t = 9).
    SphereSide functionalSide(*scene.model, scene.snapshot, rays);
    TraversalCounters work;
    const ModelHit hit = traceRay(*scene.model, rays[0], functionalSide, 0, work);
    ASSERT_TRUE(hit.hit);
    EXPECT_TRUE(hit.procedural);
    EXPECT_EQ(hit.geometryIndex, 0u);
    EXPECT_EQ(hit.primitiveIndex, 0u);
    EXPECT_FLOAT_EQ(hit.t, 5.f);
    EXPECT_EQ(work.proceduralTests, 1u);
    EXPECT_EQ(work.intersectionCalls, 1u);
    EXPECT_EQ(work.triangleTests, 1u);
    // The triangle lies beyond the committed t: tested, no candidate.
    EXPECT_EQ(functionalSide.triangleCalls, 0u);

    // Timed: same hit; the leaf occupies a primitive unit for 2 tests, then
    // one intersection round trip (cold cache, as in OneTriangleColdCache):
    // cycles = 3 (T + L) + transform + (2 - 1 + triangle.latency) + shader.intersectionLatency
    RtCore core(config, *scene.model);
    SphereSide timedSide(*scene.model, scene.snapshot, rays);
    std::vector<SimRayResult> results(1);
    core.run(rays, timedSide, results);
    EXPECT_TRUE(sameHit(results[0].hit, hit));
    EXPECT_TRUE(sameWork(results[0].work, work));
    const std::uint64_t T = (config.cache.lineBytes + config.memory.bytesPerCycle - 1) / config.memory.bytesPerCycle;
    // The BLAS leaf holds 8 + 2 x 44 = 96 bytes at 8192: two lines, missed back to back (T + T + L).
    const std::uint64_t expected = 2 * (T + config.memory.latency) + (T + T + config.memory.latency) +
                                   config.transform.latency + (2 - 1 + config.triangle.latency) +
                                   config.shader.intersectionLatency;
    EXPECT_EQ(results[0].cycles, expected);
    EXPECT_EQ(core.statsJson()["shader"]["intersectionCalls"], 1);

    // skipProcedural: the box is not tested; the triangle is hit.
    std::vector<SimRay> skipping = rays;
    skipping[0].skipProcedural = true;
    SphereSide skipSide(*scene.model, scene.snapshot, skipping);
    TraversalCounters skipWork;
    const ModelHit triangleHit = traceRay(*scene.model, skipping[0], skipSide, 0, skipWork);
    ASSERT_TRUE(triangleHit.hit);
    EXPECT_FALSE(triangleHit.procedural);
    EXPECT_EQ(triangleHit.geometryIndex, 1u);
    EXPECT_EQ(skipSide.proceduralCalls, 0u);
    EXPECT_EQ(skipWork.proceduralTests, 0u);
    // skipTriangles as well: nothing left.
    skipping[0].skipTriangles = true;
    TraversalCounters none;
    EXPECT_FALSE(traceRay(*scene.model, skipping[0], skipSide, 0, none).hit);
    EXPECT_EQ(none.triangleTests, 0u);
}

TEST(RtCoreProgrammable, AnyHitVerdictsIgnoreAndEndSearch) {
    // Two triangles in one leaf, tested in reference order: primitive 0 far
    // (z = -5, t = 6), primitive 1 near (z = -1, t = 2).
    MicroScene scene;
    scene.world.addMaterial({});
    ecs::Geometry g = oneTriangleGeometry(vec3(-1.f, -1.f, -5.f), vec3(1.f, -1.f, -5.f), vec3(0.f, 1.f, -5.f));
    g.positions.insert(g.positions.end(), {vec3(-1.f, -1.f, -1.f), vec3(1.f, -1.f, -1.f), vec3(0.f, 1.f, -1.f)});
    g.normals.resize(6, vec3(0.f, 0.f, 1.f));
    g.indices.insert(g.indices.end(), {3, 4, 5});
    const ecs::MeshId id = scene.world.addMesh(ecs::load::makeMesh("pair", g));
    const ecs::Entity e = scene.world.create("pair");
    scene.world.emplace(e, ecs::LocalTransform{vec3(0.f)});
    scene.world.emplace(e, ecs::MeshInstance{id});
    RtCoreConfig config;
    config.bvh.sahTraversalCost = 100.f;  // one leaf
    scene.build(config.bvh);
    ASSERT_TRUE(scene.model->blas(id)->bvh.root.isLeaf());
    const std::vector<SimRay> rays{simRay(makeModelRay(vec3(0.f, 0.f, 1.f), vec3(0.f, 0.f, -1.f)))};

    // Opaque: the closest, primitive 1 at t = 2.
    TraversalCounters opaqueWork;
    const ModelHit closest = traceClosestHit(*scene.model, rays[0].ray, opaqueWork);
    ASSERT_TRUE(closest.hit);
    EXPECT_EQ(closest.primitiveIndex, 1u);
    EXPECT_EQ(closest.t, 2.f);
    // Primitive 1 ignored: primitive 0 at t = 6; both tested, two shader round trips.
    FilterSide ignoreNear(1, false);
    TraversalCounters ignoreWork;
    const ModelHit far = traceRay(*scene.model, rays[0], ignoreNear, 0, ignoreWork);
    ASSERT_TRUE(far.hit);
    EXPECT_EQ(far.primitiveIndex, 0u);
    EXPECT_EQ(far.t, 6.f);
    EXPECT_EQ(ignoreWork.triangleTests, 2u);
    EXPECT_EQ(ignoreWork.anyHitCalls, 2u);
    // End search at the first commit: primitive 0 (tested first), the near one never tested.
    FilterSide endFirst(~0u, true);
    TraversalCounters endWork;
    const ModelHit first = traceRay(*scene.model, rays[0], endFirst, 0, endWork);
    ASSERT_TRUE(first.hit);
    EXPECT_EQ(first.primitiveIndex, 0u);
    EXPECT_EQ(endWork.triangleTests, 1u);

    // The timed model agrees with the functional traversal under every side,
    // and charges one any-hit round trip per shader run.
    RtCore core(config, *scene.model);
    std::vector<SimRayResult> results(1);
    FilterSide timedIgnore(1, false), timedEnd(~0u, true);
    core.run(rays, timedIgnore, results);
    EXPECT_TRUE(sameHit(results[0].hit, far));
    EXPECT_TRUE(sameWork(results[0].work, ignoreWork));
    const std::uint64_t withTwoShaders = results[0].cycles;
    core.run(rays, timedEnd, results);
    EXPECT_TRUE(sameHit(results[0].hit, first));
    EXPECT_TRUE(sameWork(results[0].work, endWork));
    // The first run was cold; compare warm runs.
    core.run(rays, timedIgnore, results);
    const std::uint64_t warmTwo = results[0].cycles;
    core.run(rays, timedEnd, results);
    const std::uint64_t warmOne = results[0].cycles;
    EXPECT_GT(withTwoShaders, warmTwo);
    // Two tests vs one on the primitive unit (one more issue cycle) and two round trips vs one.
    EXPECT_EQ(warmTwo - warmOne, 1 + config.shader.anyHitLatency);
}
