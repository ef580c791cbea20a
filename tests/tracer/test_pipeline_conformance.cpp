// DXR conformance of tracer::Pipeline: every ray flag and instance flag, the
// any-hit outcomes, closest-hit/miss selection, the shader-binding-table
// formula, the open ray interval, instance masks, hit kinds, recursion,
// procedural primitives, system values, the packet path, counters and thread
// independence. Scenes are tiny and hand-built so that every expected value
// can be worked out by hand: a "quad" is a 2x2 square in the object XY plane
// facing +z (counter-clockwise seen from +z), rays usually start at z = 10
// and go down -z, so a quad at z = 0 is hit at t = 10.
#include <rtlab/core/parallel.hpp>
#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/tracer/pipeline.hpp>

#include "reference_backend.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <cmath>
#include <memory>
#include <tuple>
#include <vector>

using namespace rtlab;
using namespace rtlab::tracer;

namespace {

// ---- payload and recording shaders -------------------------------------------

constexpr std::uint32_t kNone = 0xdeadbeefu;  // "no shader wrote this"

// What the shaders of one TraceRay saw.
struct Payload {
    int closestHits = 0;
    int misses = 0;
    int anyHits = 0;
    int intersections = 0;
    float t = -1.f;                 // RayTCurrent() in closest-hit
    std::uint32_t record = kNone;   // hit group whose closest-hit ran
    std::uint32_t missTag = kNone;  // miss shader that ran
    std::uint32_t instanceIndex = kNone;
    std::uint32_t instanceId = kNone;
    std::uint32_t geometryIndex = kNone;
    std::uint32_t primitiveIndex = kNone;
    std::uint32_t hitKind = kNone;
    std::uint32_t depth = 0;
    HitAttributes attributes;
    std::vector<float> anyHitT;  // RayTCurrent() of every any-hit call, in call order
    std::vector<int> reports;    // ReportHit() results, in call order
};

using P = Pipeline<Payload>;

P::ClosestHit recordingClosestHit(std::uint32_t record) {
    return [record](const HitContext& c, Payload& p, const HitAttributes& a) {
        ++p.closestHits;
        p.t = c.rayTCurrent;
        p.record = record;
        p.instanceIndex = c.instanceIndex;
        p.instanceId = c.instanceId;
        p.geometryIndex = c.geometryIndex;
        p.primitiveIndex = c.primitiveIndex;
        p.hitKind = c.hitKind;
        p.depth = c.recursionDepth;
        p.attributes = a;
    };
}

P::Miss recordingMiss(std::uint32_t tag) {
    return [tag](const MissContext& c, Payload& p) {
        ++p.misses;
        p.missTag = tag;
        p.depth = c.recursionDepth;
    };
}

// An any-hit that records RayTCurrent() and always answers `r`.
P::AnyHit anyHitReturning(AnyHitResult r) {
    return [r](const HitContext& c, Payload& p, const HitAttributes&) {
        ++p.anyHits;
        p.anyHitT.push_back(c.rayTCurrent);
        return r;
    };
}

// Intersection shader: a sphere of radius 1 around centers[PrimitiveIndex()]
// (object space). Reports the nearest root in (RayTMin, RayTCurrent) with
// hitKind `kind` and attributes {object normal xyz, t, 42}.
P::Intersection sphereShader(std::uint32_t kind, std::vector<vec3> centers = {vec3(0.f)}) {
    return [kind, centers](const IntersectionContext& c, Payload& p) {
        ++p.intersections;
        const vec3 o = c.objectRayOrigin() - centers.at(c.primitiveIndex);
        const vec3 d = c.objectRayDirection();
        const float a = glm::dot(d, d), b = glm::dot(o, d), k = glm::dot(o, o) - 1.f;
        const float disc = b * b - a * k;
        if (disc < 0.f) return;
        const float s = std::sqrt(disc);
        for (const float t : {(-b - s) / a, (-b + s) / a}) {
            if (!(t > c.rayTMin && t < c.rayTCurrent)) continue;
            const vec3 n = glm::normalize(o + t * d);
            HitAttributes attrs;
            attrs.values = {n.x, n.y, n.z, t, 42.f, 0.f, 0.f, 0.f};
            p.reports.push_back(c.reportHit(t, kind, attrs));
            return;
        }
    };
}

// A table of n recording hit groups sharing one any-hit and one intersection
// shader, and two recording miss shaders (tags 0 and 1).
P::Desc makeDesc(std::size_t n, P::AnyHit anyHit = {}, P::Intersection intersection = {}) {
    P::Desc desc;
    for (std::uint32_t i = 0; i < n; ++i) desc.hitGroups.push_back({recordingClosestHit(i), anyHit, intersection});
    desc.missShaders = {recordingMiss(0), recordingMiss(1)};
    return desc;
}

// ---- scene builder ------------------------------------------------------------

quat rotation(float angle, const vec3& axis) { return glm::angleAxis(angle, axis); }
const quat kIdentity{1.f, 0.f, 0.f, 0.f};
const quat kFlipX = glm::angleAxis(kPi, vec3(1.f, 0.f, 0.f));  // (x, y, z) -> (x, -y, -z): a quad then faces -z

struct TestScene {
    ecs::World world;
    ecs::MaterialId opaque = 0;
    ecs::MaterialId masked = 0;  // alphaMode Mask: a non-opaque geometry
    std::unique_ptr<AccelManager> accel;
    ecs::SceneSnapshot snapshot;
    std::unique_ptr<TraversalBackend> backend;  // nullptr: Embree (see reference_backend.hpp)
    std::uint32_t instances = 0;

    TestScene() {
        opaque = world.addMaterial(ecs::Material{});
        ecs::Material m;
        m.alphaMode = ecs::AlphaMode::Mask;
        masked = world.addMaterial(m);
    }
    ecs::MaterialId material(bool nonOpaque) const { return nonOpaque ? masked : opaque; }

    // 2x2 quad facing +z, moved by `offset` in object space.
    ecs::Geometry quadGeometry(bool nonOpaque = false, const vec3& offset = vec3(0.f)) const {
        ecs::Geometry g = ecs::load::makeQuad(2.f, 2.f, material(nonOpaque));
        for (vec3& v : g.positions) v += offset;
        return g;
    }
    // Procedural geometry: one AABB per box.
    ecs::Geometry boxGeometry(std::vector<Aabb> boxes, bool nonOpaque = false) const {
        ecs::Geometry g;
        g.material = material(nonOpaque);
        g.proceduralBoxes = std::move(boxes);
        return g;
    }
    ecs::MeshId mesh(std::vector<ecs::Geometry> geometries) {
        ecs::MeshAsset m;
        m.name = "mesh";
        m.geometries = std::move(geometries);
        return world.addMesh(std::move(m));
    }
    ecs::MeshId quad(bool nonOpaque = false) { return mesh({quadGeometry(nonOpaque)}); }
    // Unit sphere's AABB [-1, 1]^3 (use with sphereShader).
    ecs::MeshId sphere(bool nonOpaque = false) { return mesh({boxGeometry({Aabb{vec3(-1.f), vec3(1.f)}}, nonOpaque)}); }

    // One entity per instance, so the returned value is the TLAS instance index.
    std::uint32_t place(ecs::MeshId meshId, const vec3& translation, ecs::MeshInstance inst = {},
                        const quat& r = kIdentity, const vec3& scale = vec3(1.f)) {
        const ecs::Entity e = world.create();
        world.emplace(e, ecs::LocalTransform{translation, r, scale});
        inst.mesh = meshId;
        world.emplace(e, inst);
        return instances++;
    }
    ecs::MeshInstance flags(std::uint8_t f) const {
        ecs::MeshInstance i;
        i.flags = f;
        return i;
    }

    const AccelManager& build() {
        snapshot = ecs::makeSnapshot(world, world.update(0.f));
        accel = std::make_unique<AccelManager>();
        accel->update(snapshot);
        backend = tracer::testing::makeConformanceBackend(snapshot);
        return *accel;
    }
    // Builds the scene, then the pipeline on the suite's back end. (Not
    // P(s.build(), desc, s.backend.get()): argument order is unspecified, and
    // backend.get() may be read before build() creates the back end.)
    P pipeline(P::Desc desc) {
        build();
        return P(*accel, std::move(desc), backend.get());
    }
    // Another pipeline on the already built scene and the same back end.
    P another(P::Desc desc) const { return P(*accel, std::move(desc), backend.get()); }
};

// ---- rays -----------------------------------------------------------------------

// Straight down (-z) from height z above (x, y).
RayDesc down(float x, float y, float z = 10.f, float tMin = 0.f, float tMax = kInfinity) {
    return RayDesc{vec3(x, y, z), tMin, vec3(0.f, 0.f, -1.f), tMax};
}
// Straight up (+z) from depth z below (x, y).
RayDesc up(float x, float y, float z = -10.f) { return RayDesc{vec3(x, y, z), 0.f, vec3(0.f, 0.f, 1.f), kInfinity}; }

TraceArgs withFlags(std::uint32_t flags) {
    TraceArgs a;
    a.rayFlags = flags;
    return a;
}

Payload trace(const P& p, const RayDesc& ray, const TraceArgs& args = {}) {
    Payload payload;
    p.traceRay(args, ray, payload);
    return payload;
}

// A 1x1 dispatch of one traceRay, for the counters.
TraceCounters countOne(const P& p, const RayDesc& ray, const TraceArgs& args = {}) {
    return p.dispatchRays(1, 1, [&](int, int) {
        Payload payload;
        p.traceRay(args, ray, payload);
    });
}

}  // namespace

// ---- ray flags ------------------------------------------------------------------

TEST(RayFlags, ForceOpaqueSkipsAnyHitOfNonOpaqueGeometry) {
    TestScene s;
    s.place(s.quad(/*nonOpaque=*/true), vec3(0.f));
    const P p = s.pipeline(makeDesc(1, anyHitReturning(AnyHitResult::Ignore)));
    // Step: the non-opaque quad runs any-hit, which ignores the only candidate.
    const Payload a = trace(p, down(0.25f, -0.5f));
    EXPECT_EQ(a.anyHits, 1);
    EXPECT_EQ(a.misses, 1);
    EXPECT_EQ(a.closestHits, 0);
    // Step: FORCE_OPAQUE commits it without any-hit.
    const Payload b = trace(p, down(0.25f, -0.5f), withFlags(RayFlag::ForceOpaque));
    EXPECT_EQ(b.anyHits, 0);
    EXPECT_EQ(b.closestHits, 1);
    EXPECT_EQ(b.misses, 0);
    EXPECT_FLOAT_EQ(b.t, 10.f);
}

TEST(RayFlags, ForceNonOpaqueRunsAnyHitOnOpaqueGeometry) {
    TestScene s;
    s.place(s.quad(), vec3(0.f));
    const P p = s.pipeline(makeDesc(1, anyHitReturning(AnyHitResult::Ignore)));
    // Step: opaque geometry never runs any-hit.
    const Payload a = trace(p, down(0.25f, -0.5f));
    EXPECT_EQ(a.anyHits, 0);
    EXPECT_EQ(a.closestHits, 1);
    // Step: FORCE_NON_OPAQUE hands the candidate to any-hit, which ignores it.
    const Payload b = trace(p, down(0.25f, -0.5f), withFlags(RayFlag::ForceNonOpaque));
    EXPECT_EQ(b.anyHits, 1);
    ASSERT_EQ(b.anyHitT.size(), 1u);
    EXPECT_FLOAT_EQ(b.anyHitT[0], 10.f);
    EXPECT_EQ(b.closestHits, 0);
    EXPECT_EQ(b.misses, 1);
}

TEST(RayFlags, AcceptFirstHitAndEndSearchCommitsTheFirstAcceptedCandidate) {
    TestScene s;
    const ecs::MeshId glass = s.quad(true), wall = s.quad(false);
    // Step: four non-opaque quads stacked at t = 10..13 (x = 0) and four opaque ones (x = 5).
    for (int i = 0; i < 4; ++i) s.place(glass, vec3(0.f, 0.f, -float(i)));
    for (int i = 0; i < 4; ++i) s.place(wall, vec3(5.f, 0.f, -float(i)));
    const P p = s.pipeline(makeDesc(2, anyHitReturning(AnyHitResult::Accept)));
    const auto stacked = [](float t) { return t == 10.f || t == 11.f || t == 12.f || t == 13.f; };

    // Step: without the flag the closest of the four wins.
    const Payload all = trace(p, down(0.25f, -0.5f));
    EXPECT_EQ(all.closestHits, 1);
    EXPECT_FLOAT_EQ(all.t, 10.f);
    // Step: with it, the first accepted candidate is committed and nothing else is tested.
    const Payload first = trace(p, down(0.25f, -0.5f), withFlags(RayFlag::AcceptFirstHitAndEndSearch));
    EXPECT_EQ(first.anyHits, 1);
    ASSERT_EQ(first.anyHitT.size(), 1u);
    EXPECT_EQ(first.closestHits, 1);
    EXPECT_EQ(first.t, first.anyHitT[0]);
    EXPECT_TRUE(stacked(first.t)) << first.t;
    // Step: the same without any-hit (opaque stack): one hit, closest-hit once.
    const Payload opaque = trace(p, down(5.25f, -0.5f), withFlags(RayFlag::AcceptFirstHitAndEndSearch));
    EXPECT_EQ(opaque.closestHits, 1);
    EXPECT_EQ(opaque.misses, 0);
    EXPECT_EQ(opaque.anyHits, 0);
    EXPECT_TRUE(stacked(opaque.t)) << opaque.t;
}

TEST(RayFlags, AcceptFirstHitWithSkipClosestHitIsAShadowQuery) {
    TestScene s;
    const ecs::MeshId glass = s.quad(true);
    for (int i = 0; i < 4; ++i) s.place(glass, vec3(0.f, 0.f, -float(i)));
    s.place(s.quad(false), vec3(5.f, 0.f, 0.f));
    const std::uint32_t shadow = RayFlag::AcceptFirstHitAndEndSearch | RayFlag::SkipClosestHitShader;
    const P ignoring = s.pipeline(makeDesc(2, anyHitReturning(AnyHitResult::Ignore)));
    const P accepting = s.another(makeDesc(2, anyHitReturning(AnyHitResult::Accept)));
    // Step: every candidate ignored -> all four seen once, the miss shader runs.
    const Payload lit = trace(ignoring, down(0.25f, -0.5f), withFlags(shadow));
    EXPECT_EQ(lit.anyHits, 4);
    EXPECT_EQ(lit.misses, 1);
    EXPECT_EQ(lit.closestHits, 0);
    // Step: the first accepted candidate ends the search; neither closest-hit nor miss runs.
    const Payload shadowed = trace(accepting, down(0.25f, -0.5f), withFlags(shadow));
    EXPECT_EQ(shadowed.anyHits, 1);
    EXPECT_EQ(shadowed.misses, 0);
    EXPECT_EQ(shadowed.closestHits, 0);
    // Step: an opaque blocker and an empty sky.
    EXPECT_EQ(trace(accepting, down(5.25f, -0.5f), withFlags(shadow)).misses, 0);
    EXPECT_EQ(trace(accepting, down(20.f, 0.f), withFlags(shadow)).misses, 1);
    // Step: the counters see a hit of ray type 0 and no closest-hit.
    const TraceCounters c = countOne(accepting, down(5.25f, -0.5f), withFlags(shadow));
    EXPECT_EQ(c.hits[0], 1u);
    EXPECT_EQ(c.closestHitInvocations, 0u);
}

TEST(RayFlags, SkipClosestHitShaderSkipsOnlyClosestHit) {
    TestScene s;
    s.place(s.quad(), vec3(0.f));
    const P p = s.pipeline(makeDesc(1));
    // Step: a hit commits but runs no shader at all.
    const Payload hit = trace(p, down(0.25f, -0.5f), withFlags(RayFlag::SkipClosestHitShader));
    EXPECT_EQ(hit.closestHits, 0);
    EXPECT_EQ(hit.misses, 0);
    const TraceCounters c = countOne(p, down(0.25f, -0.5f), withFlags(RayFlag::SkipClosestHitShader));
    EXPECT_EQ(c.hits[0], 1u);
    EXPECT_EQ(c.closestHitInvocations, 0u);
    EXPECT_EQ(c.missInvocations, 0u);
    // Step: a miss still runs the miss shader.
    const Payload miss = trace(p, down(20.f, 0.f), withFlags(RayFlag::SkipClosestHitShader));
    EXPECT_EQ(miss.misses, 1);
    EXPECT_EQ(countOne(p, down(0.25f, -0.5f)).closestHitInvocations, 1u);
}

namespace {
// Facing layout: instance 0 faces +z at x = 0; at x = 10 a quad facing -z
// (z = 0) above one facing +z (z = -1); at x = -10 the reverse order.
struct FacingScene : TestScene {
    FacingScene() {
        const ecs::MeshId q = quad();
        place(q, vec3(0.f));
        place(q, vec3(10.f, 0.f, 0.f), {}, kFlipX);
        place(q, vec3(10.f, 0.f, -1.f));
        place(q, vec3(-10.f, 0.f, 0.f));
        place(q, vec3(-10.f, 0.f, -1.f), {}, kFlipX);
    }
};
}  // namespace

TEST(RayFlags, CullBackFacingTriangles) {
    FacingScene s;
    const P p = s.pipeline(makeDesc(1));
    const TraceArgs cull = withFlags(RayFlag::CullBackFacingTriangles);
    // Step: front faces survive, back faces are culled.
    const Payload front = trace(p, down(0.25f, -0.5f), cull);
    EXPECT_EQ(front.hitKind, kHitKindTriangleFrontFace);
    EXPECT_EQ(trace(p, up(0.25f, -0.5f)).hitKind, kHitKindTriangleBackFace);
    EXPECT_EQ(trace(p, up(0.25f, -0.5f), cull).misses, 1);
    // Step: a culled back face is as if absent: the front face behind it is hit.
    const Payload through = trace(p, down(10.25f, -0.5f), cull);
    EXPECT_EQ(through.instanceIndex, 2u);
    EXPECT_FLOAT_EQ(through.t, 11.f);
    EXPECT_EQ(through.hitKind, kHitKindTriangleFrontFace);
    EXPECT_EQ(trace(p, down(10.25f, -0.5f)).instanceIndex, 1u);
}

TEST(RayFlags, CullFrontFacingTriangles) {
    FacingScene s;
    const P p = s.pipeline(makeDesc(1));
    const TraceArgs cull = withFlags(RayFlag::CullFrontFacingTriangles);
    // Step: front faces are culled, back faces survive.
    EXPECT_EQ(trace(p, down(0.25f, -0.5f), cull).misses, 1);
    const Payload back = trace(p, up(0.25f, -0.5f), cull);
    EXPECT_EQ(back.closestHits, 1);
    EXPECT_EQ(back.hitKind, kHitKindTriangleBackFace);
    // Step: the culled front face reveals the back face behind it.
    const Payload through = trace(p, down(-9.75f, -0.5f), cull);
    EXPECT_EQ(through.instanceIndex, 4u);
    EXPECT_FLOAT_EQ(through.t, 11.f);
    EXPECT_EQ(through.hitKind, kHitKindTriangleBackFace);
    EXPECT_EQ(trace(p, down(-9.75f, -0.5f)).instanceIndex, 3u);
}

TEST(RayFlags, CullOpaque) {
    TestScene s;
    s.place(s.quad(false), vec3(0.f));            // instance 0: opaque, t = 10
    s.place(s.quad(true), vec3(0.f, 0.f, -1.f));  // instance 1: non-opaque, t = 11
    const P p = s.pipeline(makeDesc(2));
    EXPECT_EQ(trace(p, down(0.25f, -0.5f)).instanceIndex, 0u);
    // Step: the opaque quad is culled; the non-opaque one behind it is committed.
    const Payload c = trace(p, down(0.25f, -0.5f), withFlags(RayFlag::CullOpaque));
    EXPECT_EQ(c.instanceIndex, 1u);
    EXPECT_FLOAT_EQ(c.t, 11.f);
}

TEST(RayFlags, CullNonOpaque) {
    TestScene s;
    s.place(s.quad(true), vec3(0.f));              // instance 0: non-opaque, t = 10
    s.place(s.quad(false), vec3(0.f, 0.f, -1.f));  // instance 1: opaque, t = 11
    const P p = s.pipeline(makeDesc(2, anyHitReturning(AnyHitResult::Accept)));
    const Payload plain = trace(p, down(0.25f, -0.5f));
    EXPECT_EQ(plain.instanceIndex, 0u);
    // Step: the non-opaque quad is culled before its any-hit could run.
    const Payload c = trace(p, down(0.25f, -0.5f), withFlags(RayFlag::CullNonOpaque));
    EXPECT_EQ(c.instanceIndex, 1u);
    EXPECT_FLOAT_EQ(c.t, 11.f);
    EXPECT_EQ(c.anyHits, 0);
}

namespace {
// A triangle quad at z = 0 (instance 0) above a procedural unit sphere centred at z = -5 (instance 1).
struct MixedScene : TestScene {
    MixedScene() {
        place(quad(), vec3(0.f));
        place(sphere(), vec3(0.f, 0.f, -5.f));
    }
};
}  // namespace

TEST(RayFlags, SkipTriangles) {
    MixedScene s;
    const P p = s.pipeline(makeDesc(2, {}, sphereShader(3)));
    // Step: from above the quad is first...
    const Payload plain = trace(p, down(0.f, 0.f));
    EXPECT_EQ(plain.instanceIndex, 0u);
    EXPECT_FLOAT_EQ(plain.t, 10.f);
    // Step: ...unless triangles are skipped: the sphere's top (z = -4) is hit.
    const Payload skip = trace(p, down(0.f, 0.f), withFlags(RayFlag::SkipTriangles));
    EXPECT_EQ(skip.instanceIndex, 1u);
    EXPECT_FLOAT_EQ(skip.t, 14.f);
    EXPECT_EQ(skip.hitKind, 3u);
    EXPECT_EQ(skip.intersections, 1);
    // Step: a ray that only meets the quad misses.
    EXPECT_EQ(trace(p, down(0.9f, -0.9f), withFlags(RayFlag::SkipTriangles)).misses, 1);
}

TEST(RayFlags, SkipProceduralPrimitives) {
    MixedScene s;
    const P p = s.pipeline(makeDesc(2, {}, sphereShader(3)));
    // Step: from below the sphere's bottom (z = -6) is first...
    const Payload plain = trace(p, up(0.f, 0.f));
    EXPECT_EQ(plain.instanceIndex, 1u);
    EXPECT_FLOAT_EQ(plain.t, 4.f);
    // Step: ...unless procedural primitives are skipped: no intersection shader, the quad's back.
    const Payload skip = trace(p, up(0.25f, -0.5f), withFlags(RayFlag::SkipProceduralPrimitives));
    EXPECT_EQ(skip.intersections, 0);
    EXPECT_EQ(skip.instanceIndex, 0u);
    EXPECT_FLOAT_EQ(skip.t, 10.f);
    EXPECT_EQ(skip.hitKind, kHitKindTriangleBackFace);
}

// ---- instance flags -------------------------------------------------------------

TEST(InstanceFlags, TriangleCullDisable) {
    TestScene s;
    const ecs::MeshId q = s.quad();
    s.place(q, vec3(0.f));
    s.place(q, vec3(5.f, 0.f, 0.f), s.flags(InstanceFlag::TriangleCullDisable));
    const P p = s.pipeline(makeDesc(1));
    // Step: the plain instance is culled, the flagged one is not (and keeps its hit kind).
    EXPECT_EQ(trace(p, up(0.25f, -0.5f), withFlags(RayFlag::CullBackFacingTriangles)).misses, 1);
    const Payload back = trace(p, up(5.25f, -0.5f), withFlags(RayFlag::CullBackFacingTriangles));
    EXPECT_EQ(back.instanceIndex, 1u);
    EXPECT_EQ(back.hitKind, kHitKindTriangleBackFace);
    EXPECT_EQ(trace(p, down(0.25f, -0.5f), withFlags(RayFlag::CullFrontFacingTriangles)).misses, 1);
    const Payload front = trace(p, down(5.25f, -0.5f), withFlags(RayFlag::CullFrontFacingTriangles));
    EXPECT_EQ(front.instanceIndex, 1u);
    EXPECT_EQ(front.hitKind, kHitKindTriangleFrontFace);
}

TEST(InstanceFlags, TriangleFrontCounterClockwise) {
    TestScene s;
    const ecs::MeshId q = s.quad();
    s.place(q, vec3(0.f));
    s.place(q, vec3(5.f, 0.f, 0.f), s.flags(InstanceFlag::TriangleFrontCounterClockwise));
    s.place(q, vec3(10.f, 0.f, 0.f),
            s.flags(InstanceFlag::TriangleFrontCounterClockwise | InstanceFlag::TriangleCullDisable));
    const P p = s.pipeline(makeDesc(1));
    // Step: the flag swaps front and back.
    EXPECT_EQ(trace(p, down(0.25f, -0.5f)).hitKind, kHitKindTriangleFrontFace);
    EXPECT_EQ(trace(p, down(5.25f, -0.5f)).hitKind, kHitKindTriangleBackFace);
    EXPECT_EQ(trace(p, up(5.25f, -0.5f)).hitKind, kHitKindTriangleFrontFace);
    // Step: culling follows the swapped facing.
    EXPECT_EQ(trace(p, down(5.25f, -0.5f), withFlags(RayFlag::CullBackFacingTriangles)).misses, 1);
    EXPECT_EQ(trace(p, up(5.25f, -0.5f), withFlags(RayFlag::CullFrontFacingTriangles)).misses, 1);
    EXPECT_EQ(trace(p, up(5.25f, -0.5f), withFlags(RayFlag::CullBackFacingTriangles)).closestHits, 1);
    // Step: with culling disabled too, the swapped back face is kept and reported as back.
    const Payload both = trace(p, down(10.25f, -0.5f), withFlags(RayFlag::CullBackFacingTriangles));
    EXPECT_EQ(both.instanceIndex, 2u);
    EXPECT_EQ(both.hitKind, kHitKindTriangleBackFace);
}

TEST(InstanceFlags, ForceOpaque) {
    TestScene s;
    const ecs::MeshId glass = s.quad(true);
    s.place(glass, vec3(0.f));
    s.place(glass, vec3(5.f, 0.f, 0.f), s.flags(InstanceFlag::ForceOpaque));
    const P p = s.pipeline(makeDesc(1, anyHitReturning(AnyHitResult::Ignore)));
    // Step: the plain instance runs any-hit (ignored -> miss); the forced one does not.
    const Payload plain = trace(p, down(0.25f, -0.5f));
    EXPECT_EQ(plain.anyHits, 1);
    EXPECT_EQ(plain.misses, 1);
    const Payload forced = trace(p, down(5.25f, -0.5f));
    EXPECT_EQ(forced.anyHits, 0);
    EXPECT_EQ(forced.closestHits, 1);
    // Step: the forced instance counts as opaque for culling.
    EXPECT_EQ(trace(p, down(5.25f, -0.5f), withFlags(RayFlag::CullOpaque)).misses, 1);
    EXPECT_EQ(trace(p, down(5.25f, -0.5f), withFlags(RayFlag::CullNonOpaque)).closestHits, 1);
    // Step: the ray flag overrides the instance flag.
    const Payload ray = trace(p, down(5.25f, -0.5f), withFlags(RayFlag::ForceNonOpaque));
    EXPECT_EQ(ray.anyHits, 1);
    EXPECT_EQ(ray.misses, 1);
}

TEST(InstanceFlags, ForceNonOpaque) {
    TestScene s;
    const ecs::MeshId wall = s.quad(false);
    s.place(wall, vec3(0.f));
    s.place(wall, vec3(5.f, 0.f, 0.f), s.flags(InstanceFlag::ForceNonOpaque));
    const P p = s.pipeline(makeDesc(1, anyHitReturning(AnyHitResult::Ignore)));
    // Step: the plain instance is opaque; the forced one runs any-hit (ignored -> miss).
    EXPECT_EQ(trace(p, down(0.25f, -0.5f)).anyHits, 0);
    const Payload forced = trace(p, down(5.25f, -0.5f));
    EXPECT_EQ(forced.anyHits, 1);
    EXPECT_EQ(forced.misses, 1);
    // Step: it counts as non-opaque for culling.
    const Payload culled = trace(p, down(5.25f, -0.5f), withFlags(RayFlag::CullNonOpaque));
    EXPECT_EQ(culled.anyHits, 0);
    EXPECT_EQ(culled.misses, 1);
    EXPECT_EQ(trace(p, down(5.25f, -0.5f), withFlags(RayFlag::CullOpaque)).anyHits, 1);
    // Step: the ray flag overrides the instance flag.
    const Payload ray = trace(p, down(5.25f, -0.5f), withFlags(RayFlag::ForceOpaque));
    EXPECT_EQ(ray.anyHits, 0);
    EXPECT_EQ(ray.closestHits, 1);
}

// ---- any-hit outcomes -----------------------------------------------------------

namespace {
// n non-opaque quads stacked at t = 10, 11, ... (instance i at z = -i).
struct GlassStack : TestScene {
    explicit GlassStack(int n) {
        const ecs::MeshId glass = quad(true);
        for (int i = 0; i < n; ++i) place(glass, vec3(0.f, 0.f, -float(i)));
    }
};
}  // namespace

TEST(AnyHit, IgnoreHitKeepsPayloadChangesAndTraversalGoesOn) {
    GlassStack s(4);
    const P p = s.pipeline(makeDesc(1, anyHitReturning(AnyHitResult::Ignore)));
    // Step: every candidate is ignored: each is seen exactly once, then miss; payload edits survive.
    const Payload all = trace(p, down(0.25f, -0.5f));
    EXPECT_EQ(all.anyHits, 4);
    EXPECT_EQ(all.misses, 1);
    EXPECT_EQ(all.closestHits, 0);
    std::vector<float> ts = all.anyHitT;
    std::sort(ts.begin(), ts.end());
    EXPECT_EQ(ts, (std::vector<float>{10.f, 11.f, 12.f, 13.f}));

    // Step: ignoring the two nearest leaves the third as the closest hit.
    P::Desc desc = makeDesc(1, [](const HitContext& c, Payload& pl, const HitAttributes&) {
        ++pl.anyHits;
        pl.anyHitT.push_back(c.rayTCurrent);
        return c.rayTCurrent < 11.5f ? AnyHitResult::Ignore : AnyHitResult::Accept;
    });
    const P partial = s.another(std::move(desc));
    const Payload third = trace(partial, down(0.25f, -0.5f));
    EXPECT_EQ(third.closestHits, 1);
    EXPECT_FLOAT_EQ(third.t, 12.f);
    EXPECT_EQ(std::count(third.anyHitT.begin(), third.anyHitT.end(), 10.f), 1);
    EXPECT_EQ(std::count(third.anyHitT.begin(), third.anyHitT.end(), 11.f), 1);
}

TEST(AnyHit, AcceptHitAndEndSearchCommitsThatCandidate) {
    GlassStack s(2);
    const P p = s.pipeline(makeDesc(1, anyHitReturning(AnyHitResult::AcceptAndEndSearch)));
    // Step: whichever candidate traversal finds first is committed; nothing else runs.
    const Payload r = trace(p, down(0.25f, -0.5f));
    EXPECT_EQ(r.anyHits, 1);
    ASSERT_EQ(r.anyHitT.size(), 1u);
    EXPECT_EQ(r.closestHits, 1);
    EXPECT_EQ(r.t, r.anyHitT[0]);
    EXPECT_TRUE(r.t == 10.f || r.t == 11.f) << r.t;

    // Step: order-independent form: near ignored, middle ends the search, far accepted.
    GlassStack s3(3);
    const P q(s3.build(), makeDesc(1, [](const HitContext& c, Payload& pl, const HitAttributes&) {
                  ++pl.anyHits;
                  pl.anyHitT.push_back(c.rayTCurrent);
                  if (c.rayTCurrent < 10.5f) return AnyHitResult::Ignore;
                  return c.rayTCurrent < 11.5f ? AnyHitResult::AcceptAndEndSearch : AnyHitResult::Accept;
              }));
    const Payload mid = trace(q, down(0.25f, -0.5f));
    EXPECT_FLOAT_EQ(mid.t, 11.f);  // even though the near quad would be closer
    ASSERT_FALSE(mid.anyHitT.empty());
    EXPECT_EQ(mid.anyHitT.back(), 11.f);  // the search ended with it
    EXPECT_EQ(mid.closestHits, 1);
}

TEST(AnyHit, AcceptShrinksTMaxAndClosestHitGetsTheNearest) {
    GlassStack s(4);
    const P p = s.pipeline(makeDesc(1, anyHitReturning(AnyHitResult::Accept)));
    const Payload r = trace(p, down(0.25f, -0.5f));
    // Step: closest-hit runs once with the nearest t.
    EXPECT_EQ(r.closestHits, 1);
    EXPECT_FLOAT_EQ(r.t, 10.f);
    // Step: every accepted t became the new TMax: later candidates are strictly nearer.
    ASSERT_FALSE(r.anyHitT.empty());
    ASSERT_LE(r.anyHitT.size(), 4u);
    for (std::size_t i = 1; i < r.anyHitT.size(); ++i) EXPECT_LT(r.anyHitT[i], r.anyHitT[i - 1]);
    EXPECT_EQ(r.anyHitT.back(), 10.f);
}

// ---- closest-hit and miss -------------------------------------------------------

TEST(ClosestHitAndMiss, ClosestHitRunsOnceForTheClosestCommittedHit) {
    TestScene s;
    const ecs::MeshId wall = s.quad();
    // Step: far quads first so the nearest one is the last instance.
    for (int i = 3; i >= 0; --i) s.place(wall, vec3(0.f, 0.f, -float(i)));
    const P p = s.pipeline(makeDesc(1));
    const Payload r = trace(p, down(0.25f, -0.5f));
    EXPECT_EQ(r.closestHits, 1);
    EXPECT_EQ(r.misses, 0);
    EXPECT_FLOAT_EQ(r.t, 10.f);
    EXPECT_EQ(r.instanceIndex, 3u);
    EXPECT_EQ(r.depth, 1u);
    const TraceCounters c = countOne(p, down(0.25f, -0.5f));
    EXPECT_EQ(c.closestHitInvocations, 1u);
    EXPECT_EQ(c.missInvocations, 0u);
}

// The suite really runs on the back end ctest asks for (RTLAB_CONFORMANCE_BACKEND).
TEST(ClosestHitAndMiss, SuiteRunsOnTheRequestedBackEnd) {
    TestScene s;
    s.place(s.quad(), vec3(0.f));
    const P p = s.pipeline(makeDesc(1));
    const char* requested = std::getenv("RTLAB_CONFORMANCE_BACKEND");
    if (requested && *requested) {
        ASSERT_NE(p.backend(), nullptr);
        EXPECT_EQ(p.backend()->name(), std::string(requested));
    } else {
        EXPECT_EQ(p.backend(), nullptr);
    }
    EXPECT_EQ(trace(p, down(0.25f, -0.5f)).closestHits, 1);
}

// The larger instance id is reached first on the BVH back ends (its box
// starts nearer the ray origin), yet the smaller one wins the tie at t = 10.
TEST(ClosestHitAndMiss, TieGoesToTheSmallerInstanceEvenWhenFoundLast) {
    TestScene s;
    const ecs::MeshId plain = s.quad(true);
    // The same quad plus a small triangle at z = 5, off the ray's path: this
    // mesh's box starts at z = 5, so traversal enters it first.
    ecs::Geometry nearFirst = s.quadGeometry(true);
    ecs::Geometry sliver = ecs::load::makeQuad(0.1f, 0.1f, s.material(true));
    for (vec3& v : sliver.positions) v += vec3(0.9f, 0.9f, 5.f);
    const ecs::MeshId tall = s.mesh({nearFirst, sliver});
    s.place(plain, vec3(0.f));  // instance 0
    s.place(tall, vec3(0.f));   // instance 1
    const P p = s.pipeline(makeDesc(4, anyHitReturning(AnyHitResult::Accept)));
    for (const float x : {-0.5f, 0.25f}) {
        const Payload r = trace(p, down(x, -0.5f));
        EXPECT_EQ(r.closestHits, 1);
        EXPECT_EQ(r.instanceIndex, 0u) << x;
        EXPECT_FLOAT_EQ(r.t, 10.f);
        EXPECT_GE(r.anyHits, 1) << x;
    }
}

// DXR leaves ties open; rtlab commits, at equal t, the smallest (instance,
// geometry, primitive) on every back end (tracer/hit_order.hpp), so the
// committed hit never depends on traversal order.
TEST(ClosestHitAndMiss, TiesAtEqualTGoToTheSmallestIds) {
    // Step: four coincident instances of one quad -> instance 0 wherever the ray lands.
    {
        TestScene s;
        const ecs::MeshId wall = s.quad();
        for (int i = 0; i < 4; ++i) s.place(wall, vec3(0.f));
        const P p = s.pipeline(makeDesc(1));
        for (const float x : {-0.75f, -0.25f, 0.25f, 0.75f}) {
            const Payload r = trace(p, down(x, -0.5f));
            EXPECT_EQ(r.closestHits, 1);
            EXPECT_EQ(r.instanceIndex, 0u) << x;
            EXPECT_FLOAT_EQ(r.t, 10.f);
        }
    }
    // Step: two coincident geometries of one mesh -> geometry 0.
    {
        TestScene s;
        s.place(s.mesh({s.quadGeometry(), s.quadGeometry()}), vec3(0.f));
        const P p = s.pipeline(makeDesc(2));
        EXPECT_EQ(trace(p, down(0.25f, -0.5f)).geometryIndex, 0u);
        EXPECT_EQ(trace(p, down(-0.5f, 0.25f)).geometryIndex, 0u);
    }
    // Step: a ray through the diagonal both triangles of a quad share -> primitive 0.
    {
        TestScene s;
        s.place(s.quad(), vec3(0.f));
        const P p = s.pipeline(makeDesc(1));
        for (const float x : {-0.5f, 0.f, 0.25f}) {
            const Payload r = trace(p, down(x, x));
            EXPECT_EQ(r.closestHits, 1);
            EXPECT_EQ(r.primitiveIndex, 0u) << x;
        }
    }
}

TEST(ClosestHitAndMiss, MissRunsOtherwiseAndFillsThePayload) {
    TestScene s;
    s.place(s.quad(), vec3(0.f));
    P::Desc desc = makeDesc(1);
    MissContext seen;
    desc.missShaders.push_back([&seen](const MissContext& c, Payload& pl) {
        seen = c;
        ++pl.misses;
        pl.missTag = 2;
        pl.t = 123.f;
    });
    const P p = s.pipeline(std::move(desc));
    // Step: the miss shader chosen by MissShaderIndex runs once and writes the payload.
    TraceArgs args = withFlags(RayFlag::CullBackFacingTriangles);
    args.missIndex = 2;
    const Payload r = trace(p, down(20.f, 0.f, 10.f, 0.5f, 50.f), args);
    EXPECT_EQ(r.misses, 1);
    EXPECT_EQ(r.closestHits, 0);
    EXPECT_EQ(r.missTag, 2u);
    EXPECT_FLOAT_EQ(r.t, 123.f);
    // Step: MissContext carries the ray (RayTCurrent() = TMax).
    EXPECT_EQ(seen.worldRayOrigin, vec3(20.f, 0.f, 10.f));
    EXPECT_EQ(seen.worldRayDirection, vec3(0.f, 0.f, -1.f));
    EXPECT_FLOAT_EQ(seen.rayTMin, 0.5f);
    EXPECT_FLOAT_EQ(seen.rayTCurrent, 50.f);
    EXPECT_EQ(seen.rayFlags, RayFlag::CullBackFacingTriangles);
    EXPECT_EQ(seen.recursionDepth, 1u);
    // Step: miss index 1 and 0 pick their own shaders.
    args.missIndex = 1;
    EXPECT_EQ(trace(p, down(20.f, 0.f), args).missTag, 1u);
    EXPECT_EQ(trace(p, down(20.f, 0.f)).missTag, 0u);
}

// ---- shader binding table -------------------------------------------------------

namespace {
// Mesh "pair": geometry 0 at x in [-1, 1], geometry 1 at x in [2, 4]. Instance
// i sits at y = 5 i. Ray for (instance, geometry): down at (0.25 + 3 g, -0.5 + 5 i).
RayDesc pairRay(std::uint32_t instance, std::uint32_t geometry, float yStep = 5.f) {
    return down(0.25f + 3.f * float(geometry), -0.5f + yStep * float(instance));
}
}  // namespace

TEST(ShaderTable, ExplicitInstanceContributionFollowsTheDxrFormula) {
    TestScene s;
    const ecs::MeshId pair = s.mesh({s.quadGeometry(), s.quadGeometry(false, vec3(3.f, 0.f, 0.f))});
    ecs::MeshInstance a, b;
    a.hitGroupOffset = 0;
    b.hitGroupOffset = 4;
    s.place(pair, vec3(0.f), a);
    s.place(pair, vec3(0.f, 5.f, 0.f), b);
    const P p = s.pipeline(makeDesc(8));
    // Step: record = rayContribution + multiplier * geometryIndex + instanceContribution.
    for (std::uint32_t inst = 0; inst < 2; ++inst)
        for (std::uint32_t g = 0; g < 2; ++g)
            for (std::uint32_t rc = 0; rc < 2; ++rc) {
                TraceArgs args;
                args.rayContribution = rc;
                args.multiplier = 2;
                const Payload r = trace(p, pairRay(inst, g), args);
                EXPECT_EQ(r.record, rc + 2 * g + 4 * inst) << "instance " << inst << " geometry " << g << " ray " << rc;
                EXPECT_EQ(r.instanceIndex, inst);
                EXPECT_EQ(r.geometryIndex, g);
                // Step: multiplier 0 makes geometries share the instance's record.
                args.multiplier = 0;
                EXPECT_EQ(trace(p, pairRay(inst, g), args).record, rc + 4 * inst);
            }
}

TEST(ShaderTable, AutomaticInstanceContributionIsSlotBaseTimesRayTypeCount) {
    TestScene s;
    const ecs::MeshId single = s.mesh({s.quadGeometry()});
    const ecs::MeshId pair = s.mesh({s.quadGeometry(), s.quadGeometry(false, vec3(3.f, 0.f, 0.f))});
    s.place(pair, vec3(0.f));              // instance 0
    s.place(single, vec3(0.f, 5.f, 0.f));  // instance 1
    s.place(pair, vec3(0.f, 10.f, 0.f));   // instance 2
    const AccelManager& accel = s.build();
    // Step: slots are laid out per geometry, meshes in id order.
    EXPECT_EQ(accel.geometrySlotBase(single), 0u);
    EXPECT_EQ(accel.geometrySlotBase(pair), 1u);
    EXPECT_EQ(accel.geometrySlotCount(), 3u);
    P::Desc desc = makeDesc(6);
    desc.rayTypeCount = 2;
    const P p(accel, std::move(desc), s.backend.get());
    // Step: with multiplier = ray-type count, record = (slotBase + g) * 2 + rayType.
    struct Case {
        std::uint32_t instance, geometry, slot;
    };
    for (const Case c : {Case{0, 0, 1}, Case{0, 1, 2}, Case{1, 0, 0}, Case{2, 0, 1}, Case{2, 1, 2}})
        for (std::uint32_t rc = 0; rc < 2; ++rc) {
            TraceArgs args;
            args.rayContribution = rc;
            args.multiplier = 2;
            const Payload r = trace(p, pairRay(c.instance, c.geometry), args);
            EXPECT_EQ(r.instanceIndex, c.instance);
            EXPECT_EQ(r.record, c.slot * 2 + rc) << "instance " << c.instance << " geometry " << c.geometry;
        }
}

TEST(ShaderTable, ContributionAndMultiplierUseTheirLowFourBits) {
    TestScene s;
    const ecs::MeshId pair = s.mesh({s.quadGeometry(), s.quadGeometry(false, vec3(3.f, 0.f, 0.f))});
    ecs::MeshInstance a;
    a.hitGroupOffset = 0;
    s.place(pair, vec3(0.f), a);
    const P p = s.pipeline(makeDesc(8));
    // Step: 16 + 1 acts as 1, 16 + 2 as 2, 32 as 0.
    TraceArgs args;
    args.rayContribution = 16 + 1;
    args.multiplier = 16 + 2;
    EXPECT_EQ(trace(p, pairRay(0, 1), args).record, 1u + 2u);
    args.rayContribution = 32;
    EXPECT_EQ(trace(p, pairRay(0, 1), args).record, 2u);
    // Step: the ray type for statistics is masked the same way.
    args.rayContribution = 16 + 1;
    const TraceCounters c = countOne(p, pairRay(0, 1), args);
    EXPECT_EQ(c.rays[1], 1u);
    EXPECT_EQ(c.hits[1], 1u);
    EXPECT_EQ(c.rays[0], 0u);
}

TEST(ShaderTable, AnyHitComesFromTheSelectedRecord) {
    TestScene s;
    s.place(s.quad(true), vec3(0.f));
    P::Desc desc = makeDesc(2);
    desc.hitGroups[1].anyHit = anyHitReturning(AnyHitResult::Ignore);
    const P p = s.pipeline(std::move(desc));
    // Step: ray type 0 -> record 0 (no any-hit: accept); ray type 1 -> record 1 (ignores).
    const Payload r0 = trace(p, down(0.25f, -0.5f));
    EXPECT_EQ(r0.record, 0u);
    EXPECT_EQ(r0.anyHits, 0);
    TraceArgs args;
    args.rayContribution = 1;
    const Payload r1 = trace(p, down(0.25f, -0.5f), args);
    EXPECT_EQ(r1.anyHits, 1);
    EXPECT_EQ(r1.misses, 1);
}

TEST(ShaderTable, OutOfRangeHitGroupRecordThrowsPipelineError) {
    TestScene s;
    const ecs::MeshId pair = s.mesh({s.quadGeometry(), s.quadGeometry(true, vec3(3.f, 0.f, 0.f))});
    ecs::MeshInstance a, b;
    a.hitGroupOffset = 0;
    b.hitGroupOffset = 4;
    s.place(pair, vec3(0.f), a);
    s.place(pair, vec3(0.f, 5.f, 0.f), b);
    const P p = s.pipeline(makeDesc(4, anyHitReturning(AnyHitResult::Accept)));
    TraceArgs args;
    args.multiplier = 2;
    args.rayContribution = 1;
    // Step: records 0..3 exist.
    EXPECT_EQ(trace(p, pairRay(0, 1), args).record, 3u);
    // Step: instance offset 4 and contribution 3 + 2 point past the table (opaque and any-hit paths).
    EXPECT_THROW(trace(p, pairRay(1, 0), args), PipelineError);
    args.rayContribution = 3;
    EXPECT_THROW(trace(p, pairRay(0, 1), args), PipelineError);
    // Step: the dispatch paths report it too, and the pipeline stays usable.
    EXPECT_THROW(p.dispatchRays(4, 4, [&](int, int) { trace(p, pairRay(1, 0), args); }), PipelineError);
    EXPECT_THROW(p.dispatchCoherent(
                     8, 1, args, [&](int, int, Payload&) { return pairRay(1, 0); }, [](int, int, Payload&) {}),
                 PipelineError);
    EXPECT_EQ(trace(p, pairRay(0, 0)).record, 0u);
    EXPECT_EQ(trace(p, pairRay(0, 0)).depth, 1u);
}

TEST(ShaderTable, OutOfRangeMissIndexThrowsPipelineError) {
    TestScene s;
    s.place(s.quad(), vec3(0.f));
    const P p = s.pipeline(makeDesc(1));
    TraceArgs args;
    args.missIndex = 2;  // two miss shaders
    EXPECT_THROW(trace(p, down(20.f, 0.f), args), PipelineError);
    EXPECT_THROW(trace(p, down(0.25f, -0.5f), args), PipelineError);
    EXPECT_THROW(p.dispatchCoherent(
                     8, 1, args, [](int, int, Payload&) { return down(20.f, 0.f); }, [](int, int, Payload&) {}),
                 PipelineError);
    args.missIndex = 1;
    EXPECT_EQ(trace(p, down(20.f, 0.f), args).missTag, 1u);
}

// ---- ray interval, instance mask, hit kinds -------------------------------------

TEST(RayInterval, TMinAndTMaxAreOpenEnds) {
    TestScene s;
    s.place(s.quad(), vec3(0.f));
    const P p = s.pipeline(makeDesc(1));
    // Step: the quad is at exactly t = 2.
    const auto hits = [&](float tMin, float tMax) {
        return trace(p, down(0.25f, -0.5f, 2.f, tMin, tMax)).closestHits == 1;
    };
    EXPECT_TRUE(hits(0.f, kInfinity));
    EXPECT_FALSE(hits(2.f, kInfinity));  // t == TMin is outside
    EXPECT_FALSE(hits(0.f, 2.f));        // t == TMax is outside
    EXPECT_TRUE(hits(1.999f, kInfinity));
    EXPECT_TRUE(hits(0.f, 2.001f));
    EXPECT_TRUE(hits(1.999f, 2.001f));
    EXPECT_FALSE(hits(2.001f, 5.f));
    EXPECT_FLOAT_EQ(trace(p, down(0.25f, -0.5f, 2.f, 1.999f, 2.001f)).t, 2.f);
    // Step: t is in units of the (unnormalised) direction: twice as long -> half the t.
    RayDesc fast = down(0.25f, -0.5f, 2.f, 0.f, 1.001f);
    fast.direction *= 2.f;
    EXPECT_FLOAT_EQ(trace(p, fast).t, 1.f);
    fast.tMax = 1.f;
    EXPECT_EQ(trace(p, fast).misses, 1);
}

TEST(RayInterval, HitOneFloatBelowTMaxCounts) {
    TestScene s;
    s.place(s.quad(), vec3(0.f));
    const P p = s.pipeline(makeDesc(1));
    // The quad is at exactly t = 2; TMax one float above still contains it.
    const Payload r = trace(p, down(0.25f, -0.5f, 2.f, 0.f, std::nextafter(2.f, kInfinity)));
    EXPECT_EQ(r.closestHits, 1);
    EXPECT_EQ(r.t, 2.f);
    EXPECT_EQ(trace(p, down(0.25f, -0.5f, 2.f, std::nextafter(2.f, 0.f), std::nextafter(2.f, kInfinity))).closestHits,
              1);
}

TEST(InstanceMask, RayMaskAndInstanceMaskUseTheLowEightBits) {
    TestScene s;
    const ecs::MeshId q = s.quad();
    ecs::MeshInstance two, none;
    two.mask = 0x02;
    none.mask = 0x00;
    s.place(q, vec3(0.f), two);
    s.place(q, vec3(5.f, 0.f, 0.f), none);
    const P p = s.pipeline(makeDesc(1));
    const auto hits = [&](float x, std::uint32_t mask) {
        TraceArgs args;
        args.instanceInclusionMask = mask;
        return trace(p, down(x, -0.5f), args).closestHits == 1;
    };
    EXPECT_FALSE(hits(0.25f, 0x01));
    EXPECT_TRUE(hits(0.25f, 0x03));
    EXPECT_TRUE(hits(0.25f, 0x02));
    EXPECT_FALSE(hits(0.25f, 0x100));  // only the low 8 bits count: 0x100 -> 0
    EXPECT_TRUE(hits(0.25f, 0x102));
    EXPECT_FALSE(hits(0.25f, 0x00));
    EXPECT_FALSE(hits(5.25f, 0xff));  // instance mask 0: never hit
}

TEST(HitKind, FrontFaceFollowsTheWindingSeenFromTheRay) {
    TestScene s;
    // Step: the triangle (0,0,0), (1,0,0), (0,1,0); (v1-v0)x(v2-v0) = +z.
    ecs::Geometry tri;
    tri.positions = {vec3(0.f), vec3(1.f, 0.f, 0.f), vec3(0.f, 1.f, 0.f)};
    tri.normals = {vec3(0.f, 0.f, 1.f), vec3(0.f, 0.f, 1.f), vec3(0.f, 0.f, 1.f)};
    tri.indices = {0, 1, 2};
    const ecs::MeshId m = s.mesh({tri});
    s.place(m, vec3(0.f));
    s.place(m, vec3(10.f, 0.f, 0.f), {}, rotation(kPi, vec3(0.f, 1.f, 0.f)));  // turned to face -z
    const P p = s.pipeline(makeDesc(1));
    // Step: from +z going -z: dot(dir, n) < 0 -> front (254); from -z: back (255).
    const Payload front = trace(p, down(0.25f, 0.25f));
    EXPECT_EQ(front.hitKind, kHitKindTriangleFrontFace);
    EXPECT_EQ(trace(p, up(0.25f, 0.25f)).hitKind, kHitKindTriangleBackFace);
    // Step: barycentrics: u weights v1 (x), v weights v2 (y).
    EXPECT_NEAR(front.attributes.barycentrics().x, 0.25f, 1e-6f);
    EXPECT_NEAR(front.attributes.barycentrics().y, 0.25f, 1e-6f);
    // Step: facing is decided in object space: the turned instance shows its back to +z.
    const Payload turned = trace(p, down(10.f - 0.25f, 0.25f));
    EXPECT_EQ(turned.instanceIndex, 1u);
    EXPECT_EQ(turned.hitKind, kHitKindTriangleBackFace);
    EXPECT_EQ(trace(p, up(10.f - 0.25f, 0.25f)).hitKind, kHitKindTriangleFrontFace);
}

TEST(HitKind, MirroringInstanceKeepsObjectSpaceFacing) {
    TestScene s;
    // Step: scale x by -1: the world-space winding flips, the object-space ray direction does not.
    s.place(s.quad(), vec3(0.f), {}, kIdentity, vec3(-1.f, 1.f, 1.f));
    const P p = s.pipeline(makeDesc(1));
    EXPECT_EQ(trace(p, down(0.25f, -0.5f)).hitKind, kHitKindTriangleFrontFace);
    EXPECT_EQ(trace(p, up(0.25f, -0.5f)).hitKind, kHitKindTriangleBackFace);
    EXPECT_EQ(trace(p, down(0.25f, -0.5f), withFlags(RayFlag::CullBackFacingTriangles)).closestHits, 1);
}

// ---- recursion -----------------------------------------------------------------

TEST(Recursion, ClosestHitMayTraceUpToMaxRecursionDepth) {
    TestScene s;
    s.place(s.quad(), vec3(0.f));
    std::vector<std::uint32_t> depths;
    const P* self = nullptr;
    P::Desc desc;
    desc.maxRecursionDepth = 3;
    desc.hitGroups.push_back({[&](const HitContext& c, Payload& pl, const HitAttributes&) {
                                  depths.push_back(c.recursionDepth);
                                  // Step: bounce the same ray again while allowed; the last level misses.
                                  const bool last = c.recursionDepth + 1 == 3;
                                  self->traceRay({}, last ? down(20.f, 0.f) : down(0.25f, -0.5f), pl);
                              },
                              {},
                              {}});
    desc.missShaders.push_back([&](const MissContext& c, Payload& pl) {
        depths.push_back(100 + c.recursionDepth);
        ++pl.misses;
    });
    const P p = s.pipeline(std::move(desc));
    self = &p;
    const Payload r = trace(p, down(0.25f, -0.5f));
    EXPECT_EQ(depths, (std::vector<std::uint32_t>{1, 2, 103}));
    EXPECT_EQ(r.misses, 1);
    // Step: the depth is back to 0 afterwards: a new trace starts at 1.
    depths.clear();
    trace(p, down(20.f, 0.f));
    EXPECT_EQ(depths, (std::vector<std::uint32_t>{101}));
}

TEST(Recursion, ExceedingMaxRecursionDepthThrowsPipelineError) {
    TestScene s;
    s.place(s.quad(), vec3(0.f));
    const P* self = nullptr;
    std::uint32_t deepest = 0;
    P::Desc desc;
    desc.maxRecursionDepth = 2;
    desc.hitGroups.push_back({[&](const HitContext& c, Payload& pl, const HitAttributes&) {
                                  deepest = std::max(deepest, c.recursionDepth);
                                  self->traceRay({}, down(0.25f, -0.5f), pl);  // always recurses
                              },
                              {},
                              {}});
    desc.missShaders.push_back(recordingMiss(0));
    const P p = s.pipeline(std::move(desc));
    self = &p;
    EXPECT_THROW(trace(p, down(0.25f, -0.5f)), PipelineError);
    EXPECT_EQ(deepest, 2u);
    // Step: the same inside a dispatch, and the thread's depth is restored after the throw.
    EXPECT_THROW(p.dispatchRays(2, 2, [&](int, int) { trace(p, down(0.25f, -0.5f)); }), PipelineError);
    EXPECT_EQ(trace(p, down(20.f, 0.f)).depth, 1u);
    // Step: the limit itself must be in [1, 31].
    EXPECT_THROW((void)P(*s.accel, P::Desc{{}, {}, 0, 1}), PipelineError);
    EXPECT_THROW((void)P(*s.accel, P::Desc{{}, {}, 32, 1}), PipelineError);
}

// ---- procedural primitives ------------------------------------------------------

TEST(Procedural, IntersectionShaderAttributesAndHitKindReachClosestHit) {
    TestScene s;
    // Step: two boxes, spheres around (0,0,0) and (3,0,0); the instance is moved by (1,2,-3).
    const std::vector<vec3> centers = {vec3(0.f), vec3(3.f, 0.f, 0.f)};
    const ecs::MeshId m =
        s.mesh({s.boxGeometry({Aabb{vec3(-1.f), vec3(1.f)}, Aabb{vec3(2.f, -1.f, -1.f), vec3(4.f, 1.f, 1.f)}})});
    s.place(m, vec3(1.f, 2.f, -3.f));
    const P p = s.pipeline(makeDesc(1, {}, sphereShader(9, centers)));
    // Step: straight down onto the second sphere's pole (object z = 1, world z = -2 -> t = 12).
    const Payload r = trace(p, down(4.f, 2.f));
    EXPECT_EQ(r.closestHits, 1);
    EXPECT_EQ(r.hitKind, 9u);
    EXPECT_EQ(r.primitiveIndex, 1u);
    EXPECT_EQ(r.geometryIndex, 0u);
    EXPECT_FLOAT_EQ(r.t, 12.f);
    EXPECT_NEAR(r.attributes.values[0], 0.f, 1e-6f);
    EXPECT_NEAR(r.attributes.values[2], 1.f, 1e-6f);
    EXPECT_FLOAT_EQ(r.attributes.values[3], 12.f);
    EXPECT_EQ(r.attributes.values[4], 42.f);
    EXPECT_EQ(r.reports, (std::vector<int>{1}));
    // Step: through the box corner but outside the sphere: the shader runs, reports nothing, miss.
    const Payload corner = trace(p, down(1.95f, 2.95f));
    EXPECT_EQ(corner.intersections, 1);
    EXPECT_EQ(corner.misses, 1);
}

TEST(Procedural, ReportHitAcceptsOnlyTBetweenTMinAndRayTCurrent) {
    TestScene s;
    s.place(s.sphere(), vec3(0.f));
    std::vector<float> current;
    P::Desc desc = makeDesc(1, {}, [&](const IntersectionContext& c, Payload& pl) {
        ++pl.intersections;
        const HitAttributes none;
        // Step: TMin = 1 and TMax = 20 are both outside; RayTCurrent shrinks with every accepted hit.
        for (const float t : {1.f, 20.f, 0.5f, 25.f, 10.f, 12.f, 10.f, 8.f}) {
            pl.reports.push_back(c.reportHit(t, 5, none));
            current.push_back(c.rayTCurrent);
        }
    });
    const P p = s.pipeline(std::move(desc));
    const Payload r = trace(p, down(0.f, 0.f, 10.f, 1.f, 20.f));
    EXPECT_EQ(r.intersections, 1);
    EXPECT_EQ(r.reports, (std::vector<int>{0, 0, 0, 0, 1, 0, 0, 1}));
    EXPECT_EQ(current, (std::vector<float>{20.f, 20.f, 20.f, 20.f, 10.f, 10.f, 10.f, 8.f}));
    EXPECT_FLOAT_EQ(r.t, 8.f);
    EXPECT_EQ(r.hitKind, 5u);
}

TEST(Procedural, AnyHitOnNonOpaqueProceduralGeometryCanIgnore) {
    TestScene s;
    s.place(s.sphere(/*nonOpaque=*/true), vec3(0.f));
    P::Desc desc = makeDesc(
        1,
        [](const HitContext& c, Payload& pl, const HitAttributes& a) {
            ++pl.anyHits;
            pl.anyHitT.push_back(c.rayTCurrent);
            // Step: hit kind 1 is a hole, hit kind 2 is solid.
            EXPECT_EQ(a.values[0], float(c.hitKind));
            return c.hitKind == 1 ? AnyHitResult::Ignore : AnyHitResult::Accept;
        },
        [](const IntersectionContext& c, Payload& pl) {
            HitAttributes a;
            a.values[0] = 1.f;
            pl.reports.push_back(c.reportHit(10.f, 1, a));
            a.values[0] = 2.f;
            pl.reports.push_back(c.reportHit(10.5f, 2, a));
        });
    const P p = s.pipeline(std::move(desc));
    const Payload r = trace(p, down(0.f, 0.f));
    // Step: the ignored report returns false and is forgotten; the accepted one commits.
    EXPECT_EQ(r.reports, (std::vector<int>{0, 1}));
    EXPECT_EQ(r.anyHitT, (std::vector<float>{10.f, 10.5f}));
    EXPECT_FLOAT_EQ(r.t, 10.5f);
    EXPECT_EQ(r.hitKind, 2u);
    EXPECT_EQ(r.attributes.values[0], 2.f);
    // Step: FORCE_OPAQUE skips any-hit: the first report commits.
    const Payload forced = trace(p, down(0.f, 0.f), withFlags(RayFlag::ForceOpaque));
    EXPECT_EQ(forced.anyHits, 0);
    EXPECT_EQ(forced.reports, (std::vector<int>{1, 0}));
    EXPECT_EQ(forced.hitKind, 1u);
    // Step: an opaque procedural instance forced non-opaque runs any-hit too.
    TestScene o;
    o.place(o.sphere(false), vec3(0.f), o.flags(InstanceFlag::ForceNonOpaque));
    const P q(o.build(), makeDesc(1, anyHitReturning(AnyHitResult::Ignore), sphereShader(1)));
    const Payload ignored = trace(q, down(0.f, 0.f));
    EXPECT_EQ(ignored.anyHits, 1);
    EXPECT_EQ(ignored.reports, (std::vector<int>{0}));
    EXPECT_EQ(ignored.misses, 1);
}

TEST(Procedural, TwoReportsCommitTheNearer) {
    TestScene s;
    s.place(s.sphere(), vec3(0.f));
    const AccelManager& accel = s.build();
    for (const bool farFirst : {true, false}) {
        const float first = farFirst ? 11.f : 9.5f, second = farFirst ? 9.5f : 11.f;
        const P p(accel,
                  makeDesc(1, {},
                           [=](const IntersectionContext& c, Payload& pl) {
                               pl.reports.push_back(c.reportHit(first, 1, {}));
                               pl.reports.push_back(c.reportHit(second, 2, {}));
                           }),
                  s.backend.get());
        const Payload r = trace(p, down(0.f, 0.f));
        EXPECT_FLOAT_EQ(r.t, 9.5f);
        EXPECT_EQ(r.hitKind, farFirst ? 2u : 1u);
        EXPECT_EQ(r.reports, farFirst ? (std::vector<int>{1, 1}) : (std::vector<int>{1, 0}));
        // Step: ACCEPT_FIRST_HIT_AND_END_SEARCH keeps the first report, nearer or not.
        const Payload f = trace(p, down(0.f, 0.f), withFlags(RayFlag::AcceptFirstHitAndEndSearch));
        EXPECT_FLOAT_EQ(f.t, first);
        EXPECT_EQ(f.hitKind, 1u);
        EXPECT_EQ(f.reports, (std::vector<int>{1, 0}));
    }
}

TEST(Procedural, MissingIntersectionShaderOrBadHitKindThrowsPipelineError) {
    TestScene s;
    s.place(s.sphere(), vec3(0.f));
    const P none = s.pipeline(makeDesc(1));
    EXPECT_THROW(trace(none, down(0.f, 0.f)), PipelineError);
    // Step: a skipped primitive needs no shader (AABB tests may be conservative, so skip by flag).
    EXPECT_EQ(trace(none, down(0.f, 0.f), withFlags(RayFlag::SkipProceduralPrimitives)).misses, 1);
    const P bad =
        s.another(makeDesc(1, {}, [](const IntersectionContext& c, Payload&) { c.reportHit(10.f, 128, {}); }));
    EXPECT_THROW(trace(bad, down(0.f, 0.f)), PipelineError);
}

TEST(Procedural, OpacityCullingSkipsTheIntersectionShader) {
    TestScene s;
    s.place(s.sphere(false), vec3(0.f));
    s.place(s.sphere(true), vec3(5.f, 0.f, 0.f));
    const P p = s.pipeline(makeDesc(2, {}, sphereShader(1)));
    // Step: culled by opacity before intersection, as for triangles (the AABB is the candidate).
    const Payload opaque = trace(p, down(0.f, 0.f), withFlags(RayFlag::CullOpaque));
    EXPECT_EQ(opaque.misses, 1);
    EXPECT_EQ(opaque.intersections, 0);
    const Payload glass = trace(p, down(5.f, 0.f), withFlags(RayFlag::CullNonOpaque));
    EXPECT_EQ(glass.misses, 1);
    EXPECT_EQ(glass.intersections, 0);
    // Step: the other flag keeps them.
    EXPECT_EQ(trace(p, down(0.f, 0.f), withFlags(RayFlag::CullNonOpaque)).closestHits, 1);
    EXPECT_EQ(trace(p, down(5.f, 0.f), withFlags(RayFlag::CullOpaque)).closestHits, 1);
    // Step: face culling is for triangles only.
    const std::uint32_t faces = RayFlag::CullBackFacingTriangles | RayFlag::CullFrontFacingTriangles;
    EXPECT_EQ(trace(p, down(0.f, 0.f), withFlags(faces)).closestHits, 1);
    EXPECT_EQ(trace(p, up(0.f, 0.f), withFlags(faces)).closestHits, 1);
}

// ---- system values --------------------------------------------------------------

TEST(SystemValues, InstanceIdIndexGeometryAndPrimitive) {
    TestScene s;
    const ecs::MeshId pair = s.mesh({s.quadGeometry(true), s.quadGeometry(true, vec3(3.f, 0.f, 0.f))});
    ecs::MeshInstance a, c;
    a.instanceId = 0x1abcdef;  // InstanceID() keeps 24 bits
    c.instanceId = 7;
    s.place(pair, vec3(0.f), a);
    s.place(pair, vec3(0.f, 5.f, 0.f));  // automatic: the entity index
    s.place(pair, vec3(0.f, 10.f, 0.f), c);
    std::vector<std::tuple<std::uint32_t, std::uint32_t, std::uint32_t, std::uint32_t>> anyHitSaw;
    const P p = s.pipeline(makeDesc(2, [&](const HitContext& h, Payload&, const HitAttributes&) {
        anyHitSaw.emplace_back(h.instanceIndex, h.instanceId, h.geometryIndex, h.primitiveIndex);
        return AnyHitResult::Accept;
    }));
    struct Case {
        RayDesc ray;
        std::uint32_t index, id, geometry, primitive;
    };
    // Step: (0.25, -0.5) lies in triangle 0 (below the diagonal), (-0.5, 0.25) in triangle 1.
    for (const Case& k : {Case{down(0.25f, -0.5f), 0, 0xabcdef, 0, 0}, Case{down(2.5f, 5.25f), 1, 1, 1, 1},
                          Case{down(3.25f, 9.5f), 2, 7, 1, 0}, Case{down(-0.5f, 10.25f), 2, 7, 0, 1}}) {
        anyHitSaw.clear();
        const Payload r = trace(p, k.ray);
        EXPECT_EQ(r.instanceIndex, k.index);
        EXPECT_EQ(r.instanceId, k.id);
        EXPECT_EQ(r.geometryIndex, k.geometry);
        EXPECT_EQ(r.primitiveIndex, k.primitive);
        ASSERT_EQ(anyHitSaw.size(), 1u);
        EXPECT_EQ(anyHitSaw[0], std::make_tuple(k.index, k.id, k.geometry, k.primitive));
    }
}

TEST(SystemValues, ObjectSpaceOfAScaledTranslatedInstance) {
    TestScene s;
    s.place(s.quad(), vec3(3.f, 0.f, 0.f), {}, kIdentity, vec3(2.f));
    HitContext seen;
    P::Desc desc = makeDesc(1);
    desc.hitGroups[0].closestHit = [&](const HitContext& c, Payload& pl, const HitAttributes& a) {
        seen = c;
        pl.attributes = a;
        ++pl.closestHits;
    };
    const P p = s.pipeline(std::move(desc));
    const Payload r = trace(p, down(3.5f, -1.f));
    ASSERT_EQ(r.closestHits, 1);
    // Step: t is in world units; object space divides by the scale.
    EXPECT_FLOAT_EQ(seen.rayTCurrent, 10.f);
    const vec3 o = seen.objectRayOrigin(), d = seen.objectRayDirection();
    EXPECT_NEAR(o.x, 0.25f, 1e-6f);
    EXPECT_NEAR(o.y, -0.5f, 1e-6f);
    EXPECT_NEAR(o.z, 5.f, 1e-6f);
    EXPECT_NEAR(d.z, -0.5f, 1e-6f);
    const vec3 w = seen.worldHitPosition();
    EXPECT_NEAR(w.x, 3.5f, 1e-6f);
    EXPECT_NEAR(w.z, 0.f, 1e-6f);
    EXPECT_EQ(seen.objectToWorld()[3], vec4(3.f, 0.f, 0.f, 1.f));
    EXPECT_EQ(seen.objectToWorld()[0][0], 2.f);
    // Step: object hit (0.25, -0.5) on triangle 0: u = 0.375, v = 0.25.
    EXPECT_EQ(seen.primitiveIndex, 0u);
    EXPECT_NEAR(r.attributes.barycentrics().x, 0.375f, 1e-6f);
    EXPECT_NEAR(r.attributes.barycentrics().y, 0.25f, 1e-6f);
}

// ---- packet path, counters, threads --------------------------------------------

namespace {
// A little of everything: opaque and cut-out quads, a stack, a turned quad,
// a procedural sphere, and a backdrop with a gap around it.
struct ParityScene : TestScene {
    ParityScene() {
        const ecs::MeshId wall = quad(false), glass = quad(true);
        place(wall, vec3(-2.5f, 0.f, 0.f));
        place(glass, vec3(0.f, 0.f, 0.5f));
        place(glass, vec3(0.2f, 0.1f, -0.5f), {}, kFlipX);
        place(wall, vec3(-1.f, 0.5f, 1.f), flags(InstanceFlag::TriangleFrontCounterClockwise));
        place(sphere(), vec3(2.5f, 0.f, 0.f));
        place(sphere(true), vec3(3.f, 0.5f, 1.5f));
        place(mesh({quadGeometry(false), quadGeometry(true, vec3(0.f, 0.f, 0.25f))}), vec3(0.f, 0.f, -3.f), {},
              kIdentity, vec3(4.f, 1.f, 1.f));
    }
};

// Cut-out any-hit: a pure function of the candidate, so the committed hit does not depend on traversal order.
AnyHitResult cutout(const HitContext& c, Payload&, const HitAttributes& a) {
    return (a.values[0] < 0.3f || (c.primitiveIndex + c.instanceIndex) % 3 == 2) ? AnyHitResult::Ignore
                                                                                 : AnyHitResult::Accept;
}

constexpr int kGridW = 21, kGridH = 6;  // 21 = 16 + 5: partial packets and a partial tile

RayDesc parityRay(int x, int y) {
    const float wx = -5.f + (float(x) + 0.5f) * (10.f / kGridW) + 0.0131f;
    const float wy = -1.5f + (float(y) + 0.5f) * 0.5f + 0.0237f;
    // Step: odd rows look up from below, even rows down with a slight tilt.
    if (y % 2) return RayDesc{vec3(wx, wy, -10.f), 0.f, vec3(0.02f, -0.01f, 1.f), kInfinity};
    return RayDesc{vec3(wx, wy, 10.f), 0.f, vec3(-0.03f, 0.01f, -1.f), kInfinity};
}

bool samePayload(const Payload& a, const Payload& b) {
    return a.closestHits == b.closestHits && a.misses == b.misses && a.t == b.t && a.record == b.record &&
           a.missTag == b.missTag && a.instanceIndex == b.instanceIndex && a.geometryIndex == b.geometryIndex &&
           a.primitiveIndex == b.primitiveIndex && a.hitKind == b.hitKind && a.attributes.values == b.attributes.values;
}
}  // namespace

TEST(PacketPath, DispatchCoherentMatchesPerRayTraceRay) {
    ParityScene s;
    const AccelManager& accel = s.build();
    P::Desc desc = makeDesc(accel.geometrySlotCount(), cutout, sphereShader(4));
    const P p(accel, std::move(desc), s.backend.get());
    const std::uint32_t combos[] = {
        RayFlag::None,
        RayFlag::CullBackFacingTriangles,
        RayFlag::CullFrontFacingTriangles | RayFlag::ForceNonOpaque,
        RayFlag::ForceOpaque,
        RayFlag::CullOpaque,
        RayFlag::CullNonOpaque,
        RayFlag::SkipTriangles,
        RayFlag::SkipProceduralPrimitives | RayFlag::CullBackFacingTriangles,
        RayFlag::AcceptFirstHitAndEndSearch | RayFlag::SkipClosestHitShader,
    };
    for (const std::uint32_t flags : combos) {
        const TraceArgs args = withFlags(flags);
        std::vector<Payload> single(kGridW * kGridH), packet(kGridW * kGridH);
        // Step: one traceRay per pixel...
        const TraceCounters cs = p.dispatchRays(
            kGridW, kGridH, [&](int x, int y) { p.traceRay(args, parityRay(x, y), single[y * kGridW + x]); });
        // Step: ...against 8-wide packets.
        const TraceCounters cp = p.dispatchCoherent(
            kGridW, kGridH, args, [](int x, int y, Payload&) { return parityRay(x, y); },
            [&](int x, int y, Payload& pl) { packet[y * kGridW + x] = pl; });
        int hits = 0;
        for (int i = 0; i < kGridW * kGridH; ++i) {
            EXPECT_TRUE(samePayload(single[i], packet[i]))
                << "flags 0x" << std::hex << flags << std::dec << " pixel " << i << ": t " << single[i].t << " vs "
                << packet[i].t << ", instance " << single[i].instanceIndex << " vs " << packet[i].instanceIndex
                << ", primitive " << single[i].primitiveIndex << " vs " << packet[i].primitiveIndex << ", kind "
                << single[i].hitKind << " vs " << packet[i].hitKind;
            hits += single[i].misses == 0;
        }
        EXPECT_EQ(cs.hits[0], cp.hits[0]) << "flags 0x" << std::hex << flags;
        EXPECT_EQ(cs.misses[0], cp.misses[0]) << "flags 0x" << std::hex << flags;
        EXPECT_EQ(cs.closestHitInvocations, cp.closestHitInvocations);
        EXPECT_EQ(cs.missInvocations, cp.missInvocations);
        // Packets exist on the Embree path only; a back end traces whole tiles.
        if (!s.backend) {
            EXPECT_EQ(cp.packetsTraced, 3u * kGridH);  // 2 full + 1 partial packet per row
        }
        // Step: the scene is not trivial under any combination.
        EXPECT_GT(hits, 10) << "flags 0x" << std::hex << flags;
        EXPECT_LT(hits, kGridW * kGridH) << "flags 0x" << std::hex << flags;
    }
}

TEST(Counters, EqualHandCountedNumbers) {
    TestScene s;
    s.place(s.quad(false), vec3(0.f));            // A: opaque at x in [-1, 1]
    s.place(s.quad(true), vec3(4.f, 0.f, 0.f));   // B: non-opaque at x in [3, 5]
    s.place(s.quad(false), vec3(4.f, 0.f, 2.f));  // C: opaque blocker above B
    const P* self = nullptr;
    // Step: records 0..2 are A, B, C (automatic offsets); a shadow ray (type 1) hitting C uses record 3.
    P::Desc desc = makeDesc(4, anyHitReturning(AnyHitResult::Accept));
    desc.maxRecursionDepth = 2;
    // Step: closest-hit of A and B sends a shadow ray up from the hit point.
    const P::ClosestHit shade = [&](const HitContext& c, Payload& pl, const HitAttributes&) {
        TraceArgs shadow = withFlags(RayFlag::AcceptFirstHitAndEndSearch | RayFlag::SkipClosestHitShader);
        shadow.rayContribution = 1;
        shadow.multiplier = 0;
        shadow.missIndex = 1;
        self->traceRay(shadow, RayDesc{c.worldHitPosition(), 1e-3f, vec3(0.f, 0.f, 1.f), kInfinity}, pl);
    };
    desc.hitGroups[0].closestHit = shade;
    desc.hitGroups[1].closestHit = shade;
    const P p = s.pipeline(std::move(desc));
    self = &p;
    // Step: 8x2 pixels: columns 0-1 -> A from above, 2-3 -> B from below, 4-7 -> nothing.
    const TraceCounters c = p.dispatchRays(8, 2, [&](int x, int) {
        Payload pl;
        if (x < 2) p.traceRay({}, down(0.25f, -0.5f), pl);
        else if (x < 4) p.traceRay({}, up(4.25f, -0.5f), pl);
        else p.traceRay({}, down(20.f + float(x), 0.f), pl);
    });
    EXPECT_EQ(c.rays[0], 16u);
    EXPECT_EQ(c.hits[0], 8u);
    EXPECT_EQ(c.misses[0], 8u);
    EXPECT_EQ(c.rays[1], 8u);    // one shadow ray per primary hit
    EXPECT_EQ(c.hits[1], 4u);    // B's shadow rays meet C
    EXPECT_EQ(c.misses[1], 4u);  // A's see the sky
    EXPECT_EQ(c.totalRays(), 24u);
    EXPECT_EQ(c.anyHitInvocations, 4u);  // B, once per primary ray
    EXPECT_EQ(c.closestHitInvocations, 8u);
    EXPECT_EQ(c.missInvocations, 12u);
    EXPECT_EQ(c.intersectionInvocations, 0u);
    EXPECT_EQ(c.packetsTraced, 0u);
    // Step: a coherent dispatch counts its packets.
    const TraceCounters cc = p.dispatchCoherent(
        8, 2, {}, [](int x, int, Payload&) { return down(x < 4 ? 0.25f : 20.f, -0.5f); }, [](int, int, Payload&) {});
    if (!s.backend) {
        EXPECT_EQ(cc.packetsTraced, 2u);  // packets exist on the Embree path only
    }
    EXPECT_EQ(cc.rays[0], 16u);
    EXPECT_EQ(cc.hits[0], 8u);
    EXPECT_EQ(cc.rays[1], 8u);
}

TEST(Determinism, DispatchRaysIsIdenticalWithOneAndTwoThreads) {
    ParityScene s;
    const AccelManager& accel = s.build();
    const P p(accel, makeDesc(accel.geometrySlotCount(), cutout, sphereShader(4)), s.backend.get());
    constexpr int W = 48, H = 24;
    const auto run = [&](int threads, std::vector<Payload>& out) {
        const ThreadLimit limit(threads);
        out.assign(W * H, Payload{});
        return p.dispatchRays(W, H, [&](int x, int y) {
            RayDesc ray = parityRay(x % kGridW, y % kGridH);
            ray.origin.x += 0.01f * float(x / kGridW);
            p.traceRay(withFlags(y % 3 == 0 ? RayFlag::CullBackFacingTriangles : RayFlag::None), ray, out[y * W + x]);
        });
    };
    std::vector<Payload> one, two;
    const TraceCounters c1 = run(1, one);
    const TraceCounters c2 = run(2, two);
    for (int i = 0; i < W * H; ++i) EXPECT_TRUE(samePayload(one[i], two[i])) << "pixel " << i;
    EXPECT_EQ(c1.rays, c2.rays);
    EXPECT_EQ(c1.hits, c2.hits);
    EXPECT_EQ(c1.misses, c2.misses);
    EXPECT_EQ(c1.anyHitInvocations, c2.anyHitInvocations);
    EXPECT_EQ(c1.intersectionInvocations, c2.intersectionInvocations);
    EXPECT_EQ(c1.closestHitInvocations, c2.closestHitInvocations);
    EXPECT_EQ(c1.totalRays(), std::uint64_t(W * H));
}
