#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/model_scene.hpp>
#include <rtlab/rtcore_sim/traversal.hpp>
#include <gtest/gtest.h>
#include <cstdio>
using namespace rtlab; using namespace rtlab::rtcore_sim;
TEST(Scratch, Cornell) {
    ecs::World world; ecs::load::loadScene(world, "builtin:cornell");
    auto snap = ecs::makeSnapshot(world, world.update(0.f));
    ModelScene model; model.update(snap);
    const auto& camera = snap.camera; int width=320, height=240; int x=66, y=26;
    const float aspect = float(width) / float(height);
    const float tanHalf = std::tan(0.5f * camera.camera.yfov);
    const float sx = (2.f * (x + 0.5f) / width - 1.f) * tanHalf * aspect;
    const float sy = (1.f - 2.f * (y + 0.5f) / height) * tanHalf;
    const vec3 dirCamera = glm::normalize(vec3(sx, sy, -1.f));
    vec3 o = vec3(camera.worldFromCamera[3]);
    vec3 d = glm::normalize(mat3(camera.worldFromCamera) * dirCamera);
    printf("o %.9g %.9g %.9g d %.9g %.9g %.9g\n", o.x,o.y,o.z,d.x,d.y,d.z);
    for (unsigned i = 0; i < model.instances().size(); ++i) {
        const auto& inst = model.instances()[i];
        auto b = inst.worldBounds;
        auto tb = intersectBox(b, o, safeReciprocal(d), 0.f, kInfinity);
        printf("inst %u mesh %u bounds [%.9g %.9g %.9g]-[%.9g %.9g %.9g] box %s %g\n", i, inst.mesh, b.lo.x,b.lo.y,b.lo.z,b.hi.x,b.hi.y,b.hi.z, tb?"hit":"miss", tb?*tb:0.f);
        vec3 oo = vec3(inst.objectFromWorld * glm::dvec4(glm::dvec3(o),1)); vec3 od = vec3(glm::dmat3(inst.objectFromWorld)*glm::dvec3(d));
        glm::dvec3 doo = glm::dvec3(inst.objectFromWorld * glm::dvec4(glm::dvec3(o),1)); glm::dvec3 dod = glm::dmat3(inst.objectFromWorld)*glm::dvec3(d);
        const Blas* bl = model.blas(inst.mesh);
        for (std::size_t r = 0; r < bl->triangles.size(); ++r) {
            auto& t = bl->triangles[r];
            auto h = intersectTriangle(oo, od, kInfinity, t.v[0], t.v[1], t.v[2]);
            if (h) printf("   tri %zu hit t %.9g b %.9g %.9g %.9g\n", r, h->t, h->b0, h->b1, h->b2);
            // exact barycentrics in double (Moller-Trumbore in double)
            glm::dvec3 e1 = glm::dvec3(t.v[1]) - glm::dvec3(t.v[0]), e2 = glm::dvec3(t.v[2]) - glm::dvec3(t.v[0]);
            glm::dvec3 pv = glm::cross(dod, e2); double det = glm::dot(e1, pv);
            glm::dvec3 tv = doo - glm::dvec3(t.v[0]); double u = glm::dot(tv, pv) / det; glm::dvec3 qv = glm::cross(tv, e1);
            double v = glm::dot(dod, qv) / det; double tt = glm::dot(e2, qv) / det;
            if (i == 1 || i == 3) printf("   tri %zu exact t %.12g u %.6g v %.6g w %.6g\n", r, tt, u, v, 1 - u - v);
        }
        auto ob = bl->bvh.rootBounds;
        printf("   obj bounds [%.9g %.9g %.9g]-[%.9g %.9g %.9g] oo %.9g %.9g %.9g od %.9g %.9g %.9g\n", ob.lo.x,ob.lo.y,ob.lo.z,ob.hi.x,ob.hi.y,ob.hi.z, oo.x,oo.y,oo.z,od.x,od.y,od.z);
    }
    TraversalCounters c; ModelRay ray; ray.origin=o; ray.direction=d;
    auto h = traceClosestHit(model, ray, c);
    printf("trace hit %d inst %u t %g nodes %u leaves %u box %u tri %u inst %u\n", h.hit, h.instanceIndex, h.t, c.nodeVisits, c.leafVisits, c.boxTests, c.triangleTests, c.instanceTransitions);
}
