// The model's BVH: structural invariants for every width, leaf size and
// build quality, determinism, and the bottom-up refit.
#include "rtcore_test_helpers.hpp"

#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/bvh.hpp>
#include <rtlab/rtcore_sim/model_scene.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <functional>
#include <limits>
#include <map>

using namespace rtlab;
using namespace rtlab::rtcore_sim;
using rtlab::rtcore_sim::test_support::makeSoupMesh;

namespace {

bool contains(const Aabb& outer, const Aabb& inner) {
    return glm::all(glm::lessThanEqual(outer.lo, inner.lo)) && glm::all(glm::greaterThanEqual(outer.hi, inner.hi));
}
bool overlaps(const Aabb& a, const Aabb& b) {
    return glm::all(glm::lessThanEqual(a.lo, b.hi)) && glm::all(glm::lessThanEqual(b.lo, a.hi));
}

// An icosphere and a triangle soup in one mesh (two geometries).
ecs::MeshAsset makeTestMesh() {
    ecs::MeshAsset mesh = makeSoupMesh(700, 11);
    mesh.geometries.push_back(ecs::load::makeIcosphere(0.8f, 3, 0));  // 1280 triangles
    return mesh;
}

// Checks every structural invariant; `primitiveBounds(ref)` is the full box of a leaf reference.
template <class BoundsOf>
void expectValidBvh(const Bvh& bvh, std::uint32_t width, std::uint32_t maxLeafSize, bool spatialSplits,
                    std::size_t primitiveCount, BoundsOf&& primitiveBounds) {
    ASSERT_FALSE(bvh.empty());
    EXPECT_EQ(bvh.width, width);
    std::vector<int> nodeSeen(bvh.nodes.size(), 0), leafSeen(bvh.leaves.size(), 0);
    std::map<PrimitiveRef, int> refCount;
    std::uint32_t nextRef = 0;  // leaves' reference ranges follow the depth-first order
    // Every node and leaf is reached exactly once.
    const auto visitLeaf = [&](std::uint32_t index, const Aabb& box) {
        ++leafSeen[index];
        const BvhLeaf& leaf = bvh.leaves[index];
        EXPECT_GE(leaf.refCount, 1u);
        EXPECT_LE(leaf.refCount, maxLeafSize);
        EXPECT_EQ(leaf.firstRef, nextRef);
        nextRef += leaf.refCount;
        for (std::uint32_t r = leaf.firstRef; r < leaf.firstRef + leaf.refCount; ++r) {
            ++refCount[bvh.refs[r]];
            const Aabb primitive = primitiveBounds(bvh.refs[r]);
            if (spatialSplits) EXPECT_TRUE(overlaps(box, primitive));  // a clipped fragment lies in the box
            else EXPECT_TRUE(contains(box, primitive));
        }
    };
    // Pre-order walk (the layout's order): children in slot order, recursively.
    const std::function<void(std::uint32_t)> visitNode = [&](std::uint32_t n) {
        ++nodeSeen[n];
        const BvhNode& node = bvh.nodes[n];
        EXPECT_GE(node.childCount, 2u);
        EXPECT_LE(node.childCount, width);
        for (std::uint32_t i = 0; i < node.childCount; ++i) {
            const NodeRef c = node.children[i];
            ASSERT_TRUE(c.valid());
            EXPECT_TRUE(contains(bvh.rootBounds, node.childBounds[i]));
            if (c.isLeaf()) {
                visitLeaf(c.index(), node.childBounds[i]);
            } else {
                EXPECT_GT(c.index(), n);  // a parent precedes its children
                EXPECT_TRUE(contains(node.childBounds[i], bvh.nodes[c.index()].bounds()));
                visitNode(c.index());
            }
        }
    };
    if (bvh.root.isLeaf()) {
        visitLeaf(bvh.root.index(), bvh.rootBounds);
    } else {
        EXPECT_EQ(bvh.root.index(), 0u);
        visitNode(bvh.root.index());
    }
    for (int seen : nodeSeen) EXPECT_EQ(seen, 1);
    for (int seen : leafSeen) EXPECT_EQ(seen, 1);
    EXPECT_EQ(nextRef, bvh.refs.size());
    // Every primitive is referenced exactly once (at least once with spatial splits).
    EXPECT_EQ(refCount.size(), primitiveCount);
    for (const auto& [ref, count] : refCount) {
        if (spatialSplits) EXPECT_GE(count, 1);
        else EXPECT_EQ(count, 1) << "geometry " << ref.geometry << " primitive " << ref.primitive;
    }
}

Aabb triangleBounds(const ecs::MeshAsset& mesh, const PrimitiveRef& r) {
    const ecs::Geometry& g = mesh.geometries[r.geometry];
    Aabb b;
    for (int k = 0; k < 3; ++k) b.extend(g.positions[g.indices[3 * r.primitive + k]]);
    return b;
}

void expectSameBvh(const Bvh& a, const Bvh& b) {
    ASSERT_EQ(a.nodes.size(), b.nodes.size());
    ASSERT_EQ(a.leaves.size(), b.leaves.size());
    ASSERT_EQ(a.refs.size(), b.refs.size());
    EXPECT_EQ(a.root, b.root);
    for (std::size_t n = 0; n < a.nodes.size(); ++n) {
        ASSERT_EQ(a.nodes[n].childCount, b.nodes[n].childCount) << "node " << n;
        for (std::uint32_t i = 0; i < a.nodes[n].childCount; ++i) {
            EXPECT_EQ(a.nodes[n].children[i], b.nodes[n].children[i]);
            EXPECT_EQ(a.nodes[n].childBounds[i].lo, b.nodes[n].childBounds[i].lo);
            EXPECT_EQ(a.nodes[n].childBounds[i].hi, b.nodes[n].childBounds[i].hi);
        }
    }
    for (std::size_t l = 0; l < a.leaves.size(); ++l) {
        EXPECT_EQ(a.leaves[l].firstRef, b.leaves[l].firstRef);
        EXPECT_EQ(a.leaves[l].refCount, b.leaves[l].refCount);
    }
    EXPECT_TRUE(a.refs == b.refs);
}

}  // namespace

TEST(RtCoreBvh, InvariantsHoldForEveryWidthLeafSizeAndQuality) {
    const tracer::EmbreeDevice device;
    const BvhBuilder builder(device.get());
    const ecs::MeshAsset mesh = makeTestMesh();
    const std::size_t triangles = mesh.triangleCount();
    for (std::uint32_t width : {2u, 4u, 6u, 8u})
        for (std::uint32_t leafSize : {1u, 4u, 7u})
            for (BuildQuality quality : {BuildQuality::Low, BuildQuality::Medium, BuildQuality::High}) {
                SCOPED_TRACE("width " + std::to_string(width) + " leaf " + std::to_string(leafSize) + " " +
                             toString(quality));
                BvhParams params;
                params.width = width;
                params.maxLeafSize = leafSize;
                params.buildQuality = quality;
                const Blas blas = buildBlas(builder, mesh, params);
                EXPECT_EQ(blas.spatialSplits, quality == BuildQuality::High);
                expectValidBvh(blas.bvh, width, leafSize, blas.spatialSplits, triangles,
                               [&](const PrimitiveRef& r) { return triangleBounds(mesh, r); });
                ASSERT_EQ(blas.triangles.size(), blas.bvh.refs.size());
                for (std::size_t r = 0; r < blas.triangles.size(); ++r) {
                    const ecs::Geometry& g = mesh.geometries[blas.bvh.refs[r].geometry];
                    for (int k = 0; k < 3; ++k)
                        EXPECT_EQ(blas.triangles[r].v[k], g.positions[g.indices[3 * blas.bvh.refs[r].primitive + k]]);
                }
                // Wider nodes make shallower trees; the SAH cost is positive and finite.
                EXPECT_GT(blas.buildSahCost, 0.0);
                EXPECT_LT(blas.buildSahCost, 1e6);
            }
}

TEST(RtCoreBvh, SpatialSplitsDuplicateSomeReferencesAndSkipDeformableMeshes) {
    const tracer::EmbreeDevice device;
    const BvhBuilder builder(device.get());
    ecs::MeshAsset mesh = makeTestMesh();
    BvhParams params;
    params.buildQuality = BuildQuality::High;
    const Blas split = buildBlas(builder, mesh, params);
    EXPECT_TRUE(split.spatialSplits);
    EXPECT_GT(split.bvh.refs.size(), mesh.triangleCount());

    mesh.geometries[0].morphTargets.push_back(ecs::MorphTarget{});  // deformable: refits must stay tight
    const Blas deformable = buildBlas(builder, mesh, params);
    EXPECT_FALSE(deformable.spatialSplits);
    EXPECT_EQ(deformable.bvh.refs.size(), mesh.triangleCount());
}

TEST(RtCoreBvh, SmallAndEmptyInputs) {
    const tracer::EmbreeDevice device;
    const BvhBuilder builder(device.get());
    EXPECT_TRUE(builder.build({}, BuildSettings{}).empty());

    // Fewer triangles than a leaf holds: the root is a leaf.
    const ecs::MeshAsset two = ecs::load::makeMesh("quad", ecs::load::makeQuad(1.f, 1.f, 0));
    const Blas blas = buildBlas(builder, two, BvhParams{});
    ASSERT_TRUE(blas.bvh.root.isLeaf());
    EXPECT_TRUE(blas.bvh.nodes.empty());
    EXPECT_EQ(blas.bvh.refs.size(), 2u);
    EXPECT_EQ(blas.bvh.depth(), 1u);

    // Triangles with non-finite vertices are left out, as Embree does.
    ecs::MeshAsset broken = two;
    broken.geometries[0].positions[0].x = std::numeric_limits<float>::quiet_NaN();
    EXPECT_LT(buildBlas(builder, broken, BvhParams{}).bvh.refs.size(), 2u);
}

TEST(RtCoreBvh, BuildsAreDeterministicAcrossRunsAndThreadCounts) {
    const tracer::EmbreeDevice device;
    const BvhBuilder builder(device.get());
    ecs::MeshAsset mesh = makeSoupMesh(6000, 3);  // above Embree's parallel thresholds
    mesh.geometries.push_back(ecs::load::makeIcosphere(1.f, 4, 0));
    for (BuildQuality quality : {BuildQuality::Low, BuildQuality::Medium, BuildQuality::High}) {
        SCOPED_TRACE(toString(quality));
        BvhParams params;
        params.buildQuality = quality;
        const Blas first = buildBlas(builder, mesh, params);
        const Blas second = buildBlas(builder, mesh, params);
        ASSERT_GT(first.bvh.refs.size(), 0u);
        expectSameBvh(first.bvh, second.bvh);
        // Called from inside arenas of different sizes, as from worker threads.
        for (int threads : {1, 2, 4}) {
            Blas inArena;
            tbb::task_arena(threads).execute([&] { inArena = buildBlas(builder, mesh, params); });
            expectSameBvh(first.bvh, inArena.bvh);
        }
    }
}

TEST(RtCoreBvh, WidthChangesTheTree) {
    const tracer::EmbreeDevice device;
    const BvhBuilder builder(device.get());
    const ecs::MeshAsset mesh = makeTestMesh();
    BvhParams narrow, wide;
    narrow.width = 2;
    wide.width = 8;
    const Bvh a = buildBlas(builder, mesh, narrow).bvh;
    const Bvh b = buildBlas(builder, mesh, wide).bvh;
    EXPECT_GT(a.nodes.size(), b.nodes.size());
    EXPECT_GT(a.depth(), b.depth());
}

// A deformable grid instanced once, and a box.
struct DeformScene {
    ecs::World world;
    ecs::MeshId grid{}, box{};
    DeformScene() {
        world.addMaterial({});
        ecs::Geometry g = ecs::load::makeGrid(2.f, 16, 0);
        g.restPositions = g.positions;
        g.restNormals = g.normals;
        g.morphTargets.push_back(ecs::MorphTarget{std::vector<vec3>(g.positions.size(), vec3(0.f)), {}});
        grid = world.addMesh(ecs::load::makeMesh("grid", std::move(g)));
        box = world.addMesh(ecs::load::makeMesh("box", ecs::load::makeBox(vec3(1.f), 0)));
        const ecs::Entity a = world.create("grid");
        world.emplace(a, ecs::MeshInstance{grid});
        const ecs::Entity b = world.create("box");
        world.emplace(b, ecs::LocalTransform{vec3(0.f, 0.f, -5.f)});
        world.emplace(b, ecs::MeshInstance{box});
    }
    ModelUpdateStats step(ModelScene& model, float dt = 0.1f) {
        return model.update(ecs::makeSnapshot(world, world.update(dt)));
    }
};

TEST(RtCoreBvh, RefitKeepsTopologyAndBoundsContainMovedVertices) {
    DeformScene s;
    ModelScene model;
    s.step(model, 0.f);
    const Bvh before = model.blas(s.grid)->bvh;

    // A wave that moves every vertex but keeps neighbourhoods.
    s.world.deformMesh(s.grid, [](ecs::MeshAsset& m) {
        for (vec3& p : m.geometries[0].positions) p.y += 0.3f * std::sin(3.f * p.x) + 0.1f * p.z;
    });
    const ModelUpdateStats st = s.step(model);
    EXPECT_EQ(st.blasRefit, 1u);
    EXPECT_EQ(st.blasRebuilt, 0u);
    EXPECT_EQ(st.blasReused, 1u);
    EXPECT_EQ(st.tlasBuilds, 1u);  // the grid instance's world box changed

    // Same topology: nodes' children, leaves and references unchanged.
    const Blas& after = *model.blas(s.grid);
    ASSERT_EQ(after.bvh.nodes.size(), before.nodes.size());
    for (std::size_t n = 0; n < before.nodes.size(); ++n) {
        EXPECT_EQ(after.bvh.nodes[n].childCount, before.nodes[n].childCount);
        for (std::uint32_t i = 0; i < before.nodes[n].childCount; ++i)
            EXPECT_EQ(after.bvh.nodes[n].children[i], before.nodes[n].children[i]);
    }
    EXPECT_TRUE(after.bvh.refs == before.refs);
    // The refit tree is valid for the moved vertices.
    const ecs::MeshAsset& moved = s.world.mesh(s.grid);
    expectValidBvh(after.bvh, model.params().width, model.params().maxLeafSize, false, moved.triangleCount(),
                   [&](const PrimitiveRef& r) { return triangleBounds(moved, r); });
    for (std::size_t r = 0; r < after.triangles.size(); ++r)
        for (int k = 0; k < 3; ++k)
            EXPECT_EQ(after.triangles[r].v[k],
                      moved.geometries[0].positions[moved.geometries[0].indices[3 * after.bvh.refs[r].primitive + k]]);
    Aabb all;
    for (const vec3& p : moved.geometries[0].positions) all.extend(p);
    EXPECT_TRUE(contains(after.bvh.rootBounds, all));
    EXPECT_TRUE(contains(all, after.bvh.rootBounds));

    // Rays see the new surface: a vertical ray hits the grid at the moved height.
    ModelRay ray;
    ray.origin = vec3(0.05f, 5.f, 0.05f);
    ray.direction = vec3(0.f, -1.f, 0.f);
    TraversalCounters counters;
    const ModelHit hit = traceClosestHit(model, ray, counters);
    const ModelHit reference = rtcore_sim::test_support::bruteForceClosestHit(model, s.world.meshes(), ray);
    ASSERT_TRUE(hit.hit);
    EXPECT_EQ(hit.t, reference.t);
    EXPECT_EQ(hit.primitiveIndex, reference.primitiveIndex);
}

TEST(RtCoreBvh, BadlyDegradedRefitBecomesRebuildUnlessDisabled) {
    const auto scatter = [](ecs::MeshAsset& m) {
        std::uint32_t h = 12345u;
        for (vec3& p : m.geometries[0].positions) {
            h = h * 1664525u + 1013904223u;
            p.x = ((h >> 8) & 0xffff) / 65535.f * 2.f - 1.f;
            h = h * 1664525u + 1013904223u;
            p.z = ((h >> 8) & 0xffff) / 65535.f * 2.f - 1.f;
        }
    };
    {
        DeformScene s;
        ModelScene model;  // default threshold 2.0
        s.step(model, 0.f);
        s.world.deformMesh(s.grid, scatter);
        const ModelUpdateStats st = s.step(model);
        EXPECT_GT(st.worstRefitDegradation, 2.f);
        EXPECT_EQ(st.blasRebuiltForQuality, 1u);
        EXPECT_EQ(st.blasRebuilt, 1u);
        EXPECT_EQ(st.blasRefit, 0u);
    }
    {
        DeformScene s;
        BvhParams params;
        params.refitRebuildThreshold = 0.f;
        ModelScene model(params);
        s.step(model, 0.f);
        s.world.deformMesh(s.grid, scatter);
        const ModelUpdateStats st = s.step(model);
        EXPECT_EQ(st.blasRefit, 1u);
        EXPECT_EQ(st.blasRebuiltForQuality, 0u);
    }
}

TEST(RtCoreBvh, UpdateFollowsTheFrameUpdateLikeAccelManager) {
    DeformScene s;
    ModelScene model;
    ModelUpdateStats st = s.step(model, 0.f);
    EXPECT_EQ(st.blasRebuilt, 2u);
    EXPECT_EQ(st.tlasBuilds, 1u);
    EXPECT_EQ(model.instances().size(), 2u);
    expectValidBvh(model.tlas(), model.params().width, model.params().tlasMaxLeafSize, false, 2,
                   [&](const PrimitiveRef& r) { return model.instances()[r.primitive].worldBounds; });

    st = s.step(model);  // idle frame
    EXPECT_EQ(st.blasRebuilt + st.blasRefit + st.tlasBuilds, 0u);
    EXPECT_EQ(st.blasReused, 2u);

    // A moved instance: TLAS only, and its world box follows.
    ecs::Entity boxEntity;
    s.world.each<ecs::MeshInstance>([&](ecs::Entity e, const ecs::MeshInstance& m) {
        if (m.mesh == s.box) boxEntity = e;
    });
    s.world.patch<ecs::LocalTransform>(boxEntity, [](ecs::LocalTransform& t) { t.translation = vec3(0.f, 3.f, -5.f); });
    st = s.step(model);
    EXPECT_EQ(st.instancesMoved, 1u);
    EXPECT_EQ(st.tlasBuilds, 1u);
    EXPECT_EQ(st.blasRebuilt + st.blasRefit, 0u);
    EXPECT_NEAR(model.instances()[1].worldBounds.center().y, 3.f, 1e-5f);

    // A replaced mesh (new topology): rebuild.
    s.world.replaceMesh(s.box, ecs::load::makeMesh("bigger box", ecs::load::makeBox(vec3(2.f), 0)));
    st = s.step(model);
    EXPECT_EQ(st.blasRebuilt, 1u);
    EXPECT_EQ(st.tlasBuilds, 1u);
}
