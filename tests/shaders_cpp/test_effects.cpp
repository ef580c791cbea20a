// The frame plan and the effect passes: what is planned and why, that a
// skipped pass traces no rays and allocates nothing, analytic answers
// (white furnace, a mirror under an emitter, a known occluder), and no
// NaN/Inf in any buffer across stiff cases.
#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/volume_grid.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/shaders_cpp/ddgi.hpp>
#include <rtlab/shaders_cpp/frame_plan.hpp>
#include <rtlab/shaders_cpp/frame_renderer.hpp>
#include <rtlab/shaders_cpp/preview_shading.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <optional>

using namespace rtlab;
using namespace rtlab::shaders;

namespace {

struct Rendered {
    FramePlan plan;
    FrameOutput out;
};

Rendered renderWorld(ecs::World& world, RenderSettings settings = {}, PlanOptions options = {}) {
    const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, world.update(0.f));
    tracer::AccelManager accel;
    accel.update(scene);
    Rendered r;
    r.plan = planFrame(scene, options);
    r.out = renderFrame(accel, scene, r.plan, settings);
    return r;
}

Rendered renderBuiltin(const std::string& name, int w, int h, PlanOptions options = {}) {
    ecs::World world;
    ecs::load::loadScene(world, "builtin:" + name);
    RenderSettings s;
    s.width = w;
    s.height = h;
    return renderWorld(world, s, options);
}

const PassReport& report(const Rendered& r, Pass p) { return r.out.passes[static_cast<std::size_t>(p)]; }

// Every channel of the frame is finite (and nothing had to be repaired).
void expectAllFinite(const Rendered& r, const std::string& what) {
    EXPECT_EQ(r.out.nonFiniteValuesRepaired, 0u) << what;
    for (const std::string& name : r.out.image.channelNames()) {
        const float* c = r.out.image.channel(name);
        for (std::size_t i = 0; i < r.out.image.pixelCount(); ++i)
            ASSERT_TRUE(std::isfinite(c[i])) << what << " " << name;
    }
}

double meanOf(const Image& image, const std::string& channel) {
    const float* c = image.channel(channel);
    double sum = 0.0;
    for (std::size_t i = 0; i < image.pixelCount(); ++i) sum += c[i];
    return sum / double(image.pixelCount());
}

ecs::Entity addCamera(ecs::World& world, const vec3& position, const vec3& target, float yfov = 0.8f) {
    const ecs::Entity e = world.create("camera");
    world.emplace(e, ecs::LocalTransform{position, orientationLookingAlong(target - position), vec3(1.f)});
    world.emplace(e, ecs::Camera{yfov, 0.01f, 1000.f, 0.f});
    world.setActiveCamera(e);
    return e;
}

ecs::Entity place(ecs::World& world, ecs::MeshId mesh, const vec3& t, const quat& r = quat(1, 0, 0, 0),
                  const vec3& s = vec3(1.f)) {
    const ecs::Entity e = world.create();
    world.emplace(e, ecs::LocalTransform{t, r, s});
    world.emplace(e, ecs::MeshInstance{mesh});
    return e;
}

// A 40 x 40 grey (albedo 0.5) floor at y = 0, facing up; returns its material.
ecs::MaterialId addGreyFloor(ecs::World& world) {
    ecs::Material floor;
    floor.baseColor = vec4(0.5f, 0.5f, 0.5f, 1.f);
    const ecs::MaterialId id = world.addMaterial(floor);
    place(world, world.addMesh(ecs::load::makeMesh("floor", ecs::load::makeGrid(40.f, 1, id))), vec3(0.f));
    return id;
}

// `light` at `position`, facing straight down.
void addLightFacingDown(ecs::World& world, const ecs::Light& light, const vec3& position) {
    const ecs::Entity e = world.create("light");
    world.emplace(e, ecs::LocalTransform{position, orientationLookingAlong(vec3(0, -1, 0)), vec3(1.f)});
    world.emplace(e, light);
}

// The shadows pass alone, `spp` 4, on a small image.
Rendered renderShadowsOnly(ecs::World& world, int width, int height) {
    RenderSettings s;
    s.width = width;
    s.height = height;
    s.spp = 4;
    PlanOptions o;
    o.requested = {Pass::Shadows};
    return renderWorld(world, s, o);
}

}  // namespace

// ---- the plan --------------------------------------------------------------------

TEST(FramePlan, CornellNeedsShadowsAoAndGiOnly) {
    ecs::World world;
    ecs::load::loadScene(world, "builtin:cornell");
    const FramePlan plan = planFrame(ecs::makeSnapshot(world, world.update(0.f)));
    EXPECT_TRUE(plan.has(Pass::GBuffer));
    EXPECT_TRUE(plan.has(Pass::Shadows));
    EXPECT_TRUE(plan.has(Pass::AmbientOcclusion));
    EXPECT_TRUE(plan.has(Pass::GlobalIllumination));
    EXPECT_FALSE(plan.has(Pass::Reflections));
    EXPECT_FALSE(plan.has(Pass::Translucency));
    EXPECT_FALSE(plan.has(Pass::Volumes));
    EXPECT_FALSE(plan.has(Pass::AlphaMask));
    EXPECT_NE(plan[Pass::Reflections].reason.find("roughness <= 0.3"), std::string::npos) << plan.toText();
    EXPECT_NE(plan[Pass::Shadows].reason.find("1 area light"), std::string::npos) << plan.toText();
}

TEST(FramePlan, ShowcaseNeedsEveryPassWithReasons) {
    ecs::World world;
    ecs::load::loadScene(world, "builtin:showcase");
    const FramePlan plan = planFrame(ecs::makeSnapshot(world, world.update(0.f)));
    for (const PlannedPass& p : plan.passes) {
        // The path tracer is a workload, planned only on request.
        EXPECT_EQ(p.planned, p.pass != Pass::PathTrace) << passName(p.pass) << ": " << p.reason;
        EXPECT_FALSE(p.reason.empty());
    }
    // Mirror and glossy floor; the glass (transmissive) belongs to translucency.
    EXPECT_EQ(plan.facts.glossyMaterials, 2u);
    EXPECT_EQ(plan.facts.transmissiveMaterials, 1u);
    EXPECT_EQ(plan.facts.pointLights, 3u);
}

TEST(FramePlan, EffectsNarrowButNeverForce) {
    ecs::World world;
    ecs::load::loadScene(world, "builtin:cornell");
    const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, world.update(0.f));
    PlanOptions o;
    o.requested = parseEffectList("ao,reflections");
    const FramePlan plan = planFrame(scene, o);
    EXPECT_TRUE(plan.has(Pass::AmbientOcclusion));
    EXPECT_FALSE(plan.has(Pass::Shadows));
    EXPECT_FALSE(plan.has(Pass::GlobalIllumination));
    EXPECT_FALSE(plan.has(Pass::Reflections));  // asked for, but nothing glossy
    ASSERT_EQ(plan.notes.size(), 1u);
    EXPECT_NE(plan.notes[0].find("reflections requested but not planned"), std::string::npos) << plan.notes[0];
    EXPECT_TRUE(parseEffectList("auto").empty());
    EXPECT_THROW(parseEffectList("ao,glitter"), InputError);
    EXPECT_THROW(parseEffectList(","), InputError);
}

TEST(FramePlan, PathTraceOnlyOnRequest) {
    ecs::World world;
    ecs::load::loadScene(world, "builtin:cornell");
    const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, world.update(0.f));
    const FramePlan automatic = planFrame(scene);
    EXPECT_FALSE(automatic.has(Pass::PathTrace));
    EXPECT_NE(automatic[Pass::PathTrace].reason.find("--effects pathtrace"), std::string::npos);
    PlanOptions o;
    o.requested = parseEffectList("pathtrace");
    const FramePlan asked = planFrame(scene, o);
    EXPECT_TRUE(asked.has(Pass::PathTrace)) << asked.toText();
    EXPECT_TRUE(asked.has(Pass::GBuffer));
    for (Pass p : {Pass::Shadows, Pass::AmbientOcclusion, Pass::GlobalIllumination}) EXPECT_FALSE(asked.has(p));
    EXPECT_TRUE(asked.notes.empty());
    EXPECT_EQ(passFromName("pathtrace"), Pass::PathTrace);
}

// ---- what a skipped pass costs: nothing ------------------------------------------

TEST(Effects, CornellTracesNoReflectionTranslucencyVolumeOrAnyHitRays) {
    const Rendered r = renderBuiltin("cornell", 64, 48);
    for (Pass p : {Pass::Reflections, Pass::Translucency, Pass::Volumes, Pass::AlphaMask}) {
        EXPECT_EQ(report(r, p).rays, 0u) << passName(p);
        EXPECT_EQ(report(r, p).bytesAllocated, 0u) << passName(p);
    }
    EXPECT_EQ(r.out.counters.rays[kRayReflection], 0u);
    EXPECT_EQ(r.out.counters.rays[kRayTranslucency], 0u);
    EXPECT_EQ(r.out.counters.anyHitInvocations, 0u);  // FORCE_OPAQUE: no any-hit shader
    EXPECT_FALSE(r.out.image.hasChannel("reflection.R"));
    EXPECT_FALSE(r.out.image.hasChannel("volume.transmittance"));
    for (Pass p : {Pass::GBuffer, Pass::Shadows, Pass::AmbientOcclusion, Pass::GlobalIllumination}) {
        EXPECT_GT(report(r, p).rays, 0u) << passName(p);
        EXPECT_GT(report(r, p).bytesAllocated, 0u) << passName(p);
    }
    expectAllFinite(r, "cornell");
}

TEST(Effects, ShowcaseEveryEffectTracesRays) {
    const Rendered r = renderBuiltin("showcase", 64, 36);
    for (Pass p : {Pass::GBuffer, Pass::Shadows, Pass::Reflections, Pass::AmbientOcclusion, Pass::GlobalIllumination,
                   Pass::Translucency, Pass::Volumes})
        EXPECT_GT(report(r, p).rays, 0u) << passName(p);
    // Every ray type but the path tracer's bounce (a workload only planned on request).
    for (std::uint32_t t = 0; t < kRayTypeCount; ++t) {
        if (t == kRayPathBounce) continue;
        EXPECT_GT(r.out.counters.rays[t], 0u) << "ray type " << t;
    }
    EXPECT_EQ(r.out.counters.rays[kRayPathBounce], 0u);
    EXPECT_GT(r.out.counters.anyHitInvocations, 0u);  // the foliage's alpha test
    for (const char* layer : {"R",
                              "albedo.R",
                              "normal.R",
                              "geonormal.R",
                              "depth.Z",
                              "roughness.Y",
                              "metalness.Y",
                              "id.mesh",
                              "id.instance",
                              "motion.X",
                              "emissive.R",
                              "shadow.light0.V",
                              "shadow.light0.hitT",
                              "direct.light0.R",
                              "direct.point.R",
                              "reflection.R",
                              "reflection.hitT",
                              "reflection.brdf.R",
                              "ao.V",
                              "ao.hitT",
                              "gi.R",
                              "gi.hitT",
                              "translucency.R",
                              "volume.transmittance",
                              "volume.inscatter.R"})
        EXPECT_TRUE(r.out.image.hasChannel(layer)) << layer;
    expectAllFinite(r, "showcase");
}

// ---- analytic answers -------------------------------------------------------------

// White furnace: inside a closed sphere of albedo 1 emitting Le everywhere,
// every GI ray hits emission Le, so the irradiance is exactly pi Le and the
// composed radiance Le + albedo/pi x pi Le = 2 Le.
// A closed white rough sphere emitting Le = 0.5 around the camera.
static void buildWhiteFurnace(ecs::World& world) {
    ecs::Material m;
    m.baseColor = vec4(1.f);
    m.roughness = 1.f;
    m.emissive = vec3(0.5f);
    const ecs::MaterialId mat = world.addMaterial(m);
    place(world, world.addMesh(ecs::load::makeMesh("furnace", ecs::load::makeIcosphere(5.f, 3, mat))), vec3(0.f));
    addCamera(world, vec3(0.f), vec3(0.f, 0.f, -1.f));
}

TEST(Effects, WhiteFurnaceGiIsPiTimesEmission) {
    ecs::World world;
    buildWhiteFurnace(world);
    RenderSettings s;
    s.width = 32;
    s.height = 24;
    s.spp = 4;
    const Rendered r = renderWorld(world, s);
    ASSERT_TRUE(r.plan.has(Pass::GlobalIllumination)) << r.plan.toText();
    EXPECT_NEAR(meanOf(r.out.image, "gi.G"), kPi * 0.5, 0.01 * kPi * 0.5);
    EXPECT_NEAR(meanOf(r.out.image, "G"), 2.0 * 0.5, 0.01 * 1.0);
    expectAllFinite(r, "furnace");
}

// Inside a closed white emitter (Le = 0.5, no lights) every bounce hits and
// adds Le x throughput: depth 0 is exactly Le, and D bounces give Le x sum
// over k <= D of rho^k, rho = the BRDF's directional albedo (Lambert 1 plus
// the dielectric GGX lobe's few percent).
TEST(Effects, PathTraceFurnaceSumsOneEmissionPerBounce) {
    const auto render = [](int depth) {
        ecs::World world;  // a fresh world per render: a second update would report nothing new
        buildWhiteFurnace(world);
        PlanOptions o;
        o.requested = parseEffectList("pathtrace");
        RenderSettings s;
        s.width = 32;
        s.height = 24;
        s.spp = 4;
        s.pathMaxDepth = depth;
        return renderWorld(world, s, o);
    };
    const Rendered direct = render(0);
    ASSERT_TRUE(direct.plan.has(Pass::PathTrace)) << direct.plan.toText();
    EXPECT_DOUBLE_EQ(meanOf(direct.out.image, "pathtrace.G"), 0.5);
    EXPECT_EQ(direct.out.counters.rays[kRayPathBounce], 0u);
    ASSERT_EQ(direct.out.pathVertices.size(), 1u);

    const Rendered paths = render(3);
    const double mean = meanOf(paths.out.image, "pathtrace.G");
    EXPECT_GT(mean, 0.5 * 4 * 0.995);
    EXPECT_LT(mean, 0.5 * 4 * 1.15);
    EXPECT_DOUBLE_EQ(meanOf(paths.out.image, "G"), mean);  // the beauty is the path tracer's estimate
    ASSERT_EQ(paths.out.pathVertices.size(), 4u);
    EXPECT_EQ(paths.out.pathVertices[0].bounceRays, 0u);
    for (std::size_t d = 1; d < 4; ++d) {
        EXPECT_GT(paths.out.pathVertices[d].bounceRays, 0u) << d;
        EXPECT_EQ(paths.out.pathVertices[d].bounceHits, paths.out.pathVertices[d].bounceRays) << d;  // closed
        EXPECT_EQ(paths.out.pathVertices[d].shadowRays, 0u) << d;  // no light to sample
    }
    EXPECT_EQ(paths.out.counters.rays[kRayPathBounce], paths.out.pathVertices[1].bounceRays +
                                                           paths.out.pathVertices[2].bounceRays +
                                                           paths.out.pathVertices[3].bounceRays);
    expectAllFinite(paths, "path-traced furnace");
}

// A deeper path only adds light (the random numbers of the first vertices do
// not depend on the depth), and on the showcase (mirror, glass, fog, alpha
// cut-outs) nothing goes non-finite.
TEST(Effects, PathTraceDeeperPathsOnlyAddLight) {
    PlanOptions o;
    o.requested = parseEffectList("pathtrace");
    const auto render = [&](const std::string& scene, int depth) {
        ecs::World world;
        ecs::load::loadScene(world, "builtin:" + scene);
        RenderSettings s;
        s.width = 48;
        s.height = 32;
        s.spp = 2;
        s.pathMaxDepth = depth;
        return renderWorld(world, s, o);
    };
    const Rendered shallow = render("cornell", 1), deep = render("cornell", 3);
    ASSERT_TRUE(deep.plan.has(Pass::PathTrace));
    const std::vector<vec3> a = shallow.out.image.rgbLayer("pathtrace"), b = deep.out.image.rgbLayer("pathtrace");
    std::size_t brighter = 0;
    for (std::size_t i = 0; i < a.size(); ++i)
        for (int c = 0; c < 3; ++c) {
            EXPECT_GE(b[i][c], a[i][c] * (1.f - 1e-5f)) << "pixel " << i;
            brighter += b[i][c] > a[i][c] * 1.001f;
        }
    EXPECT_GT(brighter, a.size());  // most pixels gain light from the extra bounces
    EXPECT_GT(deep.out.counters.rays[kRayPathBounce], shallow.out.counters.rays[kRayPathBounce]);
    EXPECT_GT(deep.out.counters.rays[kRayShadow], shallow.out.counters.rays[kRayShadow]);
    const Rendered showcase = render("showcase", 4);
    EXPECT_GT(showcase.out.counters.rays[kRayPathBounce], 0u);
    expectAllFinite(showcase, "path-traced showcase");
}

// A mirror (roughness 0, metallic, albedo 1) seen at 45 degrees reflects an
// emitting panel that fills the reflected view: the reflection layer is the
// panel's radiance, the pre-integrated term of a white metal ~ 1.
TEST(Effects, MirrorReflectsEmitterExactly) {
    for (const float roughness : {0.f, 1e-4f}) {
        ecs::World world;
        ecs::Material mirror;
        mirror.baseColor = vec4(1.f);
        mirror.metallic = 1.f;
        mirror.roughness = roughness;
        ecs::Material panel;
        panel.baseColor = vec4(0.f, 0.f, 0.f, 1.f);
        panel.emissive = vec3(2.f, 1.f, 0.5f);
        const ecs::MaterialId mirrorId = world.addMaterial(mirror), panelId = world.addMaterial(panel);
        place(world, world.addMesh(ecs::load::makeMesh("mirror", ecs::load::makeGrid(4.f, 1, mirrorId))), vec3(0.f));
        // A huge panel at x = -20 facing +x: every reflected ray of the camera meets it.
        place(world, world.addMesh(ecs::load::makeMesh("panel", ecs::load::makeQuad(400.f, 400.f, panelId))),
              vec3(-20.f, 0.f, 0.f), glm::angleAxis(0.5f * kPi, vec3(0, 1, 0)));
        addCamera(world, vec3(1.f, 1.f, 0.f), vec3(0.f), 0.2f);
        RenderSettings s;
        s.width = 16;
        s.height = 16;
        const Rendered r = renderWorld(world, s);
        ASSERT_TRUE(r.plan.has(Pass::Reflections)) << r.plan.toText();
        EXPECT_NEAR(meanOf(r.out.image, "reflection.R"), 2.0, 2e-3) << roughness;
        EXPECT_NEAR(meanOf(r.out.image, "reflection.B"), 0.5, 1e-3) << roughness;
        EXPECT_NEAR(meanOf(r.out.image, "reflection.brdf.R"), 1.0, 0.02) << roughness;
        expectAllFinite(r, "mirror");
    }
}

// A small rect light 2 units above a floor, an occluder quad over the left
// half: pixels under it see visibility 0, the others 1; the unshadowed
// direct light matches the small-source formula Le A / h^2 x albedo / pi.
TEST(Effects, KnownOccluderShadowAndUnshadowedLight) {
    // The world, with the camera looking straight down at the floor point (cameraX, 0, 0).
    const auto render = [](float cameraX) {
        ecs::World world;
        const ecs::MaterialId floorId = addGreyFloor(world);
        // Occluder: a quad at height 1 covering x in [-20, -0.5].
        place(world, world.addMesh(ecs::load::makeMesh("occluder", ecs::load::makeGrid(19.5f, 1, floorId))),
              vec3(-10.25f, 1.f, 0.f), quat(1, 0, 0, 0), vec3(1.f, 1.f, 40.f / 19.5f));
        ecs::Light light{ecs::LightType::Rect, vec3(1.f), 100.f};
        light.size = vec2(0.05f, 0.05f);
        addLightFacingDown(world, light, vec3(0.f, 2.f, 0.f));
        addCamera(world, vec3(cameraX, 0.9f, 0.f), vec3(cameraX, 0.f, 0.f), 0.2f);
        return renderShadowsOnly(world, 8, 8);
    };
    // Step: lit floor around x = 0.5 (the pixels span about +-0.09).
    const Rendered lit = render(0.5f);
    const float* V = lit.out.image.channel("shadow.light0.V");
    const float* U = lit.out.image.channel("direct.light0.R");
    for (std::size_t i = 0; i < lit.out.image.pixelCount(); ++i) EXPECT_EQ(V[i], 1.f) << i;
    // Small-source irradiance E = Le A cos^2 / d^2 (cos = h / d); radiance = albedo / pi E.
    const double d2 = 0.5 * 0.5 + 2.0 * 2.0;
    const double cosine = 2.0 / std::sqrt(d2);
    const double expected = 0.5 / kPi * 100.0 * 0.05 * 0.05 * cosine * cosine / d2;
    // The centre pixels straddle x = 0.5 by half a pixel: 3% covers that and the source size.
    EXPECT_NEAR(U[4 * 8 + 4], expected, 0.03 * expected);
    EXPECT_NEAR(U[3 * 8 + 3], expected, 0.03 * expected);
    expectAllFinite(lit, "lit");
    // Step: under the occluder (x = -2): no light; the shadow ray toward the
    // light (0, 2, 0) climbs at 45 degrees and meets the occluder (height 1) at t = sqrt(2).
    const Rendered shadowed = render(-2.f);
    const float* V2 = shadowed.out.image.channel("shadow.light0.V");
    const float* hitT = shadowed.out.image.channel("shadow.light0.hitT");
    for (std::size_t i = 0; i < shadowed.out.image.pixelCount(); ++i) {
        EXPECT_EQ(V2[i], 0.f) << i;
        EXPECT_NEAR(hitT[i], std::sqrt(2.f), 0.1f) << i;  // pixels span x = -2 +- 0.09
    }
    expectAllFinite(shadowed, "occluder");
}

// ---- stiff cases -------------------------------------------------------------------

TEST(Effects, StiffCasesStayFinite) {
    // Roughness 0, 1e-4 and 1 on the showcase floor; a zero-radius sphere
    // light; fog with extinction x distance ~ 1e4.
    for (const float roughness : {0.f, 1e-4f, 1.f}) {
        ecs::World world;
        ecs::load::loadScene(world, "builtin:showcase");
        for (ecs::MaterialId id = 0; id < world.materials().size(); ++id)
            world.patchMaterial(id, [&](ecs::Material& m) { m.roughness = roughness; });
        ecs::Light sphere{ecs::LightType::Sphere, vec3(1.f), 50.f};
        sphere.radius = 0.f;
        const ecs::Entity le = world.create("dot light");
        world.emplace(le, ecs::LocalTransform{vec3(0.f, 2.f, 0.f)});
        world.emplace(le, sphere);
        world.each<ecs::Volume>([&](ecs::Entity e, const ecs::Volume&) {
            world.patch<ecs::Volume>(e, [](ecs::Volume& v) { v.densityScale = 5000.f; });
        });
        RenderSettings s;
        s.width = 48;
        s.height = 27;
        const Rendered r = renderWorld(world, s);
        expectAllFinite(r, "roughness " + std::to_string(roughness));
        // Dense fog: the primary rays through it are (almost) fully absorbed.
        EXPECT_LT(meanOf(r.out.image, "volume.transmittance"), 0.999);
    }
}

namespace {
// Cornell with every root entity moved by `offset` and scaled by `scale`
// about the origin (camera and light included).
Rendered renderCornellTransformed(const vec3& offset, float scale) {
    ecs::World world;
    ecs::load::loadScene(world, "builtin:cornell");
    std::vector<ecs::Entity> roots;
    world.each<ecs::LocalTransform>([&](ecs::Entity e, const ecs::LocalTransform&) {
        if (!world.has<ecs::Parent>(e)) roots.push_back(e);
    });
    for (const ecs::Entity e : roots)
        world.patch<ecs::LocalTransform>(e, [&](ecs::LocalTransform& t) {
            t.translation = t.translation * scale + offset;
            if (!world.has<ecs::Light>(e) && !world.has<ecs::Camera>(e)) t.scale *= scale;
        });
    world.each<ecs::Light>([&](ecs::Entity e, const ecs::Light&) {
        world.patch<ecs::Light>(e, [&](ecs::Light& l) { l.size *= scale; });  // radiance (nits) is scale-free
    });
    RenderSettings s;
    s.width = 48;
    s.height = 36;
    s.aoRadius = 0.3f * scale;
    return renderWorld(world, s);
}
}  // namespace

// Far from the origin (1e5) and at a tiny scale (1e-4) the ray offsets keep
// surfaces from shadowing themselves and shadow rays from overshooting
// their lights: AO, light visibility and GI match the untransformed render
// (same random numbers; differences come from float rounding only).
TEST(Effects, FarAndTinySceneHasNoSelfIntersectionAcne) {
    const Rendered base = renderCornellTransformed(vec3(0.f), 1.f);
    const Rendered far = renderCornellTransformed(vec3(1e5f, 0.f, 1e5f), 1.f);
    const Rendered tiny = renderCornellTransformed(vec3(0.f), 1e-4f);
    // Tiny: float precision scales with the scene: the same up to rounding.
    expectAllFinite(tiny, "tiny");
    EXPECT_NEAR(meanOf(tiny.out.image, "ao.V"), meanOf(base.out.image, "ao.V"), 0.005);
    EXPECT_NEAR(meanOf(tiny.out.image, "shadow.light0.V"), meanOf(base.out.image, "shadow.light0.V"), 0.005);
    EXPECT_NEAR(meanOf(tiny.out.image, "gi.G"), meanOf(base.out.image, "gi.G"), 0.02 * meanOf(base.out.image, "gi.G"));
    // Far: at 1e5 one ulp is 8 mm and ray offsets are ~6 cm in a 2 m room, so
    // corners open up a little (measured: AO -1 %, GI +6 %); no acne (that
    // would darken AO and shadows by tens of percent).
    expectAllFinite(far, "far");
    EXPECT_NEAR(meanOf(far.out.image, "ao.V"), meanOf(base.out.image, "ao.V"), 0.02);
    EXPECT_NEAR(meanOf(far.out.image, "shadow.light0.V"), meanOf(base.out.image, "shadow.light0.V"), 0.01);
    EXPECT_NEAR(meanOf(far.out.image, "gi.G"), meanOf(base.out.image, "gi.G"), 0.1 * meanOf(base.out.image, "gi.G"));
}

// ---- DDGI ------------------------------------------------------------------------

// Inside an emitting sphere of albedo 0 every probe ray sees Le: the probes
// hold pi Le after one frame and every surface reads it back.
TEST(Effects, DdgiFurnaceIsPiTimesEmission) {
    ecs::World world;
    ecs::Material m;
    m.baseColor = vec4(0.f, 0.f, 0.f, 1.f);
    m.emissive = vec3(0.5f);
    const ecs::MaterialId mat = world.addMaterial(m);
    // Facing inward (a room): probes inside see front faces, the ones in the
    // bounding box's corners outside the sphere see back faces (inside geometry).
    ecs::Geometry shell = ecs::load::makeIcosphere(5.f, 3, mat);
    for (std::size_t i = 0; i < shell.indices.size(); i += 3) std::swap(shell.indices[i + 1], shell.indices[i + 2]);
    for (vec3& n : shell.normals) n = -n;
    place(world, world.addMesh(ecs::load::makeMesh("furnace", std::move(shell))), vec3(0.f));
    addCamera(world, vec3(0.f), vec3(0.f, 0.f, -1.f));
    const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, world.update(0.f));
    tracer::AccelManager accel;
    accel.update(scene);
    PlanOptions o;
    o.gi = GiTechnique::Ddgi;
    const FramePlan plan = planFrame(scene, o);
    ASSERT_TRUE(plan.has(Pass::GlobalIllumination));
    RenderSettings s;
    s.width = 24;
    s.height = 16;
    FrameHistory history;
    const FrameOutput out = renderFrame(accel, scene, plan, s, history);
    ASSERT_TRUE(history.ddgi);
    EXPECT_GT(out.ddgiAtlas.width(), 0);
    const float* gi = out.image.channel("gi.G");
    // Every probe inside the sphere holds exactly pi Le.
    const DdgiVolume& volume = *history.ddgi;
    for (std::uint32_t p = 0; p < volume.probeCount(); ++p) {
        if (glm::length(volume.probePosition(p)) < 4.5f) {
            EXPECT_NEAR(volume.probeIrradiance(p, vec3(0.f, 0.f, 1.f)).y, kPi * 0.5f, 1e-3f) << p;
        }
    }
    // Surfaces: the corner probes outside the sphere see only back faces;
    // classified inactive, they are left out. Active probes straddling the
    // shell have a few texels that saw only back faces (still 0 after one
    // frame): 2%.
    std::uint32_t inactive = 0;
    for (std::uint32_t p = 0; p < volume.probeCount(); ++p) inactive += !volume.probeActive(p);
    EXPECT_GT(inactive, 0u);
    for (std::size_t i = 0; i < out.image.pixelCount(); ++i) EXPECT_NEAR(gi[i], kPi * 0.5f, 0.02f * kPi * 0.5f) << i;
}

// DDGI's irradiance on Cornell after a few frames against path tracing: no
// less than 5% below the one-bounce path GI pass (energy loss would show
// here), and the beauty (direct + DDGI) no brighter than the path tracer's
// (8 bounces): DDGI adds bounces through its feedback, never more than all
// of them. Measured (mean G): gi pass 0.0735, DDGI 0.104 (relocated probes
// keep more of the multi-bounce light; 0.075 without relocation); beauty
// direct only 0.0290, direct + DDGI 0.0485, path tracer 0.0574.
TEST(Effects, DdgiCornellAgreesWithPathGiOnAverage) {
    ecs::World world;
    ecs::load::loadScene(world, "builtin:cornell");
    const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, world.update(0.f));
    tracer::AccelManager accel;
    accel.update(scene);
    RenderSettings s;
    s.width = 48;
    s.height = 36;
    PlanOptions o;
    o.requested = {Pass::PathTrace};
    s.spp = 64;
    s.pathMaxDepth = 8;
    const FrameOutput reference = renderFrame(accel, scene, planFrame(scene, o), s);
    o.requested = {Pass::GlobalIllumination};
    s.spp = 16;
    const FrameOutput path = renderFrame(accel, scene, planFrame(scene, o), s);
    o.requested = {Pass::Shadows, Pass::GlobalIllumination};
    o.gi = GiTechnique::Ddgi;
    FrameHistory history;
    FrameOutput ddgi;
    for (std::uint32_t f = 0; f < 6; ++f) {
        s.frame = f;
        ddgi = renderFrame(accel, scene, planFrame(scene, o), s, history);
    }
    const double p = meanOf(path.image, "gi.G"), d = meanOf(ddgi.image, "gi.G");
    EXPECT_GT(p, 0.0);
    EXPECT_GE(d, 0.95 * p);
    const double beauty = meanOf(ddgi.image, "G"), all = meanOf(reference.image, "G");
    EXPECT_LE(beauty, 1.02 * all);
    EXPECT_GE(beauty, 0.8 * all);
    EXPECT_EQ(ddgi.nonFiniteValuesRepaired, 0u);
}

// ---- motion vectors ------------------------------------------------------------

// Showcase frame 1 after frame 0: the camera stands still, so static
// surfaces have zero motion; the sliding box's pixels point back to where
// the box was (it moves toward +x and +z between the frames).
TEST(Effects, MotionVectorsBackProjectMovingInstances) {
    ecs::World world;
    ecs::load::loadScene(world, "builtin:showcase");
    tracer::AccelManager accel;
    RenderSettings s;
    s.width = 96;
    s.height = 54;
    PlanOptions o;
    o.requested = {Pass::GBuffer};
    FrameHistory history;
    FrameOutput out;
    for (int f = 0; f < 2; ++f) {
        const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, world.update(f == 0 ? 0.f : 0.25f));
        accel.update(scene);
        s.frame = static_cast<std::uint32_t>(f);
        out = renderFrame(accel, scene, planFrame(scene, o), s, history);
    }
    // Which instance is the moving box? The only one whose pixels move,
    // besides the waving cloth (deforming: MotionVectorsFollowDeformingVertices).
    const float* mx = out.image.channel("motion.X");
    const float* my = out.image.channel("motion.Y");
    const float* inst = out.image.channel("id.instance");
    const float* mesh = out.image.channel("id.mesh");
    float clothMesh = -1.f;
    for (std::size_t m = 0; m < world.meshes().size(); ++m)
        if (world.meshes()[m].name == "waving cloth") clothMesh = float(m);
    ASSERT_GE(clothMesh, 0.f);
    std::size_t moving = 0, still = 0, clothMoving = 0;
    float movingInstance = -1.f;
    for (std::size_t i = 0; i < out.image.pixelCount(); ++i) {
        const bool moved = std::abs(mx[i]) > 0.05f || std::abs(my[i]) > 0.05f;
        if (moved && mesh[i] == clothMesh) {
            ++clothMoving;
        } else if (moved) {
            if (movingInstance < 0.f) movingInstance = inst[i];
            EXPECT_EQ(inst[i], movingInstance) << "only one rigid instance moves";
            ++moving;
        } else {
            ++still;
        }
        EXPECT_TRUE(std::isfinite(mx[i]) && std::isfinite(my[i]));
    }
    EXPECT_GT(moving, 20u);
    EXPECT_GT(clothMoving, 20u);
    EXPECT_GT(still, out.image.pixelCount() / 2);
    // The box moves right on screen (+x world, camera looking down -z): its
    // previous position lies to the left, so motion.x < 0.
    double sumX = 0.0;
    for (std::size_t i = 0; i < out.image.pixelCount(); ++i)
        if (inst[i] == movingInstance) sumX += mx[i];
    EXPECT_LT(sumX, 0.0);
}

// A 2 x 2 grid facing the camera 3 units away, deformed by one morph target
// that shifts each vertex along x by 0.2 + 0.2 z (object space: a shear, so
// different rows move by different amounts). Frame 0 at weight 0, frame 1 at
// weight 1, camera and instance still: every grid pixel's motion vector
// must point to where the same material point (rest position r with r + delta(r)
// = the hit) was projected in frame 0. The deformation is linear, so the
// triangles interpolate it exactly and the answer is exact up to float.
TEST(Effects, MotionVectorsFollowDeformingVertices) {
    ecs::World world;
    ecs::Material mat;
    const ecs::MaterialId id = world.addMaterial(mat);
    ecs::Geometry grid = ecs::load::makeGrid(2.f, 8, id);
    ecs::MorphTarget shear;
    for (const vec3& p : grid.positions) shear.positionDeltas.emplace_back(0.2f + 0.2f * p.z, 0.f, 0.f);
    grid.restPositions = grid.positions;
    grid.restNormals = grid.normals;
    grid.morphTargets.push_back(std::move(shear));
    const quat facing = glm::angleAxis(0.5f * kPi, vec3(1.f, 0.f, 0.f));  // object +y (the grid's normal) -> world +z
    const ecs::Entity e =
        place(world, world.addMesh(ecs::load::makeMesh("sheared grid", std::move(grid))), vec3(0.f), facing);
    world.emplace(e, ecs::MorphWeights{{0.f}});
    addCamera(world, vec3(0.f, 0.f, 3.f), vec3(0.f));
    tracer::AccelManager accel;
    RenderSettings s;
    s.width = 48;
    s.height = 36;
    PlanOptions o;
    o.requested = {Pass::GBuffer};
    FrameHistory history;
    FrameOutput out;
    ecs::CameraSnapshot camera;
    mat4 worldFromObject(1.f);
    for (int f = 0; f < 2; ++f) {
        if (f == 1) world.patch<ecs::MorphWeights>(e, [](ecs::MorphWeights& w) { w.weights = {1.f}; });
        const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, world.update(f == 0 ? 0.f : 0.1f));
        accel.update(scene);
        camera = scene.camera;
        worldFromObject = scene.instances.at(0).worldFromObject;
        s.frame = static_cast<std::uint32_t>(f);
        out = renderFrame(accel, scene, planFrame(scene, o), s, history);
    }
    const float* mx = out.image.channel("motion.X");
    const float* my = out.image.channel("motion.Y");
    const float* mesh = out.image.channel("id.mesh");
    const mat4 objectFromWorld = glm::inverse(worldFromObject);
    const PinholeCamera pinhole(camera, s.width, s.height);
    std::size_t checked = 0;
    float worst = 0.f;
    for (int y = 0; y < s.height; ++y)
        for (int x = 0; x < s.width; ++x) {
            const std::size_t i = std::size_t(y) * s.width + x;
            if (mesh[i] < 0.f) continue;
            const CameraRay r = pinhole.ray(x + 0.5f, y + 0.5f);
            const vec3 hit = r.origin + r.direction * (-r.origin.z / r.direction.z);  // the plane z = 0
            const vec3 c = vec3(objectFromWorld * vec4(hit, 1.f));
            const vec3 rest(c.x - 0.2f - 0.2f * c.z, 0.f, c.z);
            const std::optional<vec2> before = pinhole.project(vec3(worldFromObject * vec4(rest, 1.f)));
            ASSERT_TRUE(before.has_value());
            const vec2 expected = *before - vec2(x + 0.5f, y + 0.5f);
            worst = std::max({worst, std::abs(mx[i] - expected.x), std::abs(my[i] - expected.y)});
            ++checked;
        }
    EXPECT_GT(checked, 200u);
    // Rows move by 0.2 .. 0.4 world units, 3.6 .. 7.3 pixels: a wrong answer
    // (0 from the instance transform alone) misses by pixels.
    EXPECT_LT(worst, 0.02f);
}

// ---- light units -------------------------------------------------------------------

namespace {
// A grey floor seen straight down at the origin, lit by one light; the
// unshadowed (area) or shadowed (point) direct light of the centre pixel.
float directAtFloorCentre(const ecs::Light& light, const vec3& lightPosition, const char* layer) {
    ecs::World world;
    addGreyFloor(world);
    addLightFacingDown(world, light, lightPosition);
    addCamera(world, vec3(0.f, 0.5f, 0.f), vec3(0.f), 0.01f);
    const Rendered r = renderShadowsOnly(world, 3, 3);
    expectAllFinite(r, layer);
    return r.out.image.channel(layer)[4];
}
}  // namespace

// The floor's BRDF seen and lit head-on: Lambert albedo / pi plus the GGX
// lobe of the default material (roughness 1: D = 1/pi, G2 = 1, F = 0.04): 0.04 / (4 pi).
constexpr double kHeadOnBrdf = 0.5 / kPi + 0.04 / (4.0 * kPi);

// A sphere light of radius r at height d straight above: irradiance
// E = pi Le (r/d)^2 exactly. Small and distant spheres (r/d = 1e-4) too:
// the cone is sampled from sin^2 / (1 + cos), not 1 - cos.
TEST(Effects, SphereLightIrradianceIsAnalytic) {
    for (const float ratio : {0.2f, 1e-2f, 1e-4f}) {
        ecs::Light sphere{ecs::LightType::Sphere, vec3(1.f), 1000.f};
        sphere.radius = 2.f * ratio;
        const double expected = kHeadOnBrdf * kPi * 1000.0 * double(ratio) * double(ratio);
        const float got = directAtFloorCentre(sphere, vec3(0.f, 2.f, 0.f), "direct.light0.R");
        EXPECT_NEAR(got, expected, 0.01 * expected) << "r/d " << ratio;
    }
}

// Point lights are in candela: E = I cos / d^2.
TEST(Effects, PointLightIsInCandela) {
    ecs::Light point{ecs::LightType::Point, vec3(1.f), 40.f};
    const float got = directAtFloorCentre(point, vec3(0.f, 2.f, 0.f), "direct.point.R");
    const double expected = kHeadOnBrdf * 40.0 / 4.0;
    EXPECT_NEAR(got, expected, 1e-3 * expected);
}

// Up to four point lights each get a shadow ray (direct.point, exact at 1
// spp); with more, one is picked per pixel by importance (direct.pointPicked,
// right on average). Lights at height 2 over the floor centre, one apart.
TEST(Effects, FewPointLightsAreTracedEachManyArePicked) {
    std::uint64_t shadowRays = 0;
    const auto render = [&shadowRays](int lights, int spp, const char* layer, double& expected) {
        ecs::World world;
        addGreyFloor(world);
        expected = 0.0;
        for (int k = 0; k < lights; ++k) {
            const vec3 position(0.5f * float(k) - 1.f, 2.f, 0.3f);
            addLightFacingDown(world, ecs::Light{ecs::LightType::Point, vec3(1.f), 40.f}, position);
            // E = I cos / d^2 at the floor centre times the Lambert term albedo / pi.
            const double d2 = glm::dot(position, position), cosI = position.y / std::sqrt(d2);
            expected += 40.0 * cosI / d2 * (0.5 / kPi);
        }
        addCamera(world, vec3(0.f, 0.5f, 0.f), vec3(0.f), 0.01f);
        RenderSettings s;
        s.width = s.height = 3;
        s.spp = spp;
        PlanOptions o;
        o.requested = {Pass::Shadows};
        const Rendered r = renderWorld(world, s, o);
        expectAllFinite(r, layer);
        EXPECT_EQ(r.out.image.hasChannel("direct.point.R"), lights <= 4);
        EXPECT_EQ(r.out.image.hasChannel("direct.pointPicked.R"), lights > 4);
        shadowRays = r.out.counters.rays[kRayShadow];
        return r.out.image.channel(layer)[4];
    };
    double diffuseFour = 0.0, diffuseSix = 0.0;
    const float four = render(4, 1, "direct.point.R", diffuseFour);
    const float six = render(6, 256, "direct.pointPicked.R", diffuseSix);
    // The default material adds a small GGX lobe (F0 0.04) to the Lambert term: within 4 %.
    EXPECT_NEAR(four, diffuseFour, 0.04 * diffuseFour);
    EXPECT_GT(four, diffuseFour);
    EXPECT_NEAR(six, diffuseSix, 0.08 * diffuseSix);
    EXPECT_EQ(shadowRays, 256u * 9u);  // picked: one light per pixel and sample
    // Traced without fog, every sample's ray is the same: one per light and
    // pixel at any spp, and the same value.
    double unused = 0.0;
    EXPECT_EQ(render(4, 16, "direct.point.R", unused), four);
    EXPECT_EQ(shadowRays, 4u * 9u);
}
