// renderFrame: the planned passes in order, then the composed beauty image.
#include "render_context.hpp"

#include <rtlab/core/timer.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

namespace rtlab::shaders {

void FrameHistory::record(const ecs::SceneSnapshot& scene) {
    valid = true;
    camera = scene.camera;
    std::uint32_t capacity = 0;
    for (const ecs::InstanceSnapshot& inst : scene.instances) capacity = std::max(capacity, inst.entity.index + 1);
    worldFromObject.assign(capacity, mat4(1.f));
    present.assign(capacity, false);
    for (const ecs::InstanceSnapshot& inst : scene.instances) {
        worldFromObject[inst.entity.index] = inst.worldFromObject;
        present[inst.entity.index] = true;
    }
    // Deformed vertices (outputs of the ECS deformation systems, overwritten
    // by the next update): copied, for deforming meshes only.
    const std::size_t meshCount = scene.meshes ? scene.meshes->size() : 0;
    deformedPositions.resize(meshCount);
    for (std::size_t m = 0; m < meshCount; ++m) {
        const ecs::MeshAsset& mesh = (*scene.meshes)[m];
        const bool deforming = std::any_of(mesh.geometries.begin(), mesh.geometries.end(),
                                           [](const ecs::Geometry& g) { return g.deformable(); });
        auto& copy = deformedPositions[m];
        if (!deforming) {
            copy.clear();
            continue;
        }
        copy.resize(mesh.geometries.size());
        for (std::size_t g = 0; g < mesh.geometries.size(); ++g) copy[g] = mesh.geometries[g].positions;
    }
}

std::string_view rayTypeName(std::uint32_t rayType) {
    static constexpr std::array<std::string_view, kRayTypeCount> kNames = {
        "primary", "shadow", "reflection", "ao", "gi", "translucency", "pathBounce"};
    return rayType < kRayTypeCount ? kNames[rayType] : std::string_view("unknown");
}

namespace {

// A frame's layers as the compose reads them; absent layers count as 0 (T as 1).
struct ComposeLayers {
    std::vector<vec3> albedo, emissive, point, gi, reflection, brdf, translucency, inscatter, pathTraced;
    const float* metalness = nullptr;
    const float* transmission = nullptr;
    const float* transmittance = nullptr;
    const float* mesh = nullptr;
    std::vector<std::vector<vec3>> unshadowed;
    std::vector<const float*> visibility;

    explicit ComposeLayers(const Image& frame) {
        const auto rgb = [&](const std::string& layer) -> std::vector<vec3> {
            return frame.hasChannel(layer.empty() ? "R" : layer + ".R") ? frame.rgbLayer(layer) : std::vector<vec3>();
        };
        albedo = rgb("albedo"), emissive = rgb("emissive"), gi = rgb("gi");
        // The point lights: traced one by one (direct.point) or picked per pixel (direct.pointPicked).
        point = frame.hasChannel("direct.pointPicked.R") ? rgb("direct.pointPicked") : rgb("direct.point");
        reflection = rgb("reflection"), brdf = rgb("reflection.brdf"), translucency = rgb("translucency");
        inscatter = rgb("volume.inscatter");
        pathTraced = rgb("pathtrace");
        metalness = frame.channel("metalness.Y");
        transmission = frame.channel("transmission.Y");
        transmittance = frame.channel("volume.transmittance");
        mesh = frame.channel("id.mesh");
        for (int i = 0; frame.hasChannel("direct.light" + std::to_string(i) + ".R"); ++i) {
            unshadowed.push_back(rgb("direct.light" + std::to_string(i)));
            visibility.push_back(frame.channel("shadow.light" + std::to_string(i) + ".V"));
        }
    }
    static vec3 at(const std::vector<vec3>& layer, std::size_t p) { return layer.empty() ? vec3(0.f) : layer[p]; }
    bool geometry(std::size_t p) const { return mesh && mesh[p] >= 0.f; }
    float transmissionAt(std::size_t p) const { return transmission ? transmission[p] : 0.f; }
    // Sum over area lights of unshadowed x visibility, plus the point lights.
    vec3 direct(std::size_t p) const {
        vec3 d(0.f);
        for (std::size_t l = 0; l < unshadowed.size(); ++l)
            d += unshadowed[l][p] * (visibility[l] ? visibility[l][p] : 1.f);
        if (!point.empty()) d += point[p];
        return d;
    }
    // (1 - metalness)(1 - transmission) albedo / pi x E.
    vec3 diffuseIndirect(std::size_t p) const {
        const float m = metalness ? metalness[p] : 0.f;
        return (1.f - m) * (1.f - transmissionAt(p)) * at(albedo, p) * at(gi, p) / kPi;
    }
    vec3 specular(std::size_t p) const {
        return brdf.empty() || reflection.empty() ? vec3(0.f) : brdf[p] * reflection[p];
    }
    vec3 transmitted(std::size_t p) const { return transmissionAt(p) * at(translucency, p); }
};

}  // namespace

void composeBeauty(Image& frame) {
    const std::size_t n = frame.pixelCount();
    const ComposeLayers c(frame);
    std::vector<vec3> beauty(n, vec3(0.f));
    for (std::size_t p = 0; p < n; ++p) {
        beauty[p] = ComposeLayers::at(c.inscatter, p);
        if (!c.geometry(p)) continue;
        const float T = c.transmittance ? c.transmittance[p] : 1.f;
        if (!c.pathTraced.empty()) {
            beauty[p] += T * c.pathTraced[p];  // the path tracer's layer is the whole estimate
            continue;
        }
        beauty[p] += T * (ComposeLayers::at(c.emissive, p) + c.direct(p) + c.diffuseIndirect(p) + c.specular(p) +
                          c.transmitted(p));
    }
    if (frame.hasChannel("R")) {
        float* r = frame.channel("R");
        float* g = frame.channel("G");
        float* b = frame.channel("B");
        for (std::size_t p = 0; p < n; ++p) {
            r[p] = beauty[p].x;
            g[p] = beauty[p].y;
            b[p] = beauty[p].z;
        }
    } else {
        frame.addRgbLayer("", beauty);
    }
}

std::vector<vec3> effectContribution(const Image& frame, const std::string& effect) {
    const std::size_t n = frame.pixelCount();
    const ComposeLayers c(frame);
    const float* ao = frame.channel("ao.V");
    std::vector<vec3> out(n, vec3(0.f));
    for (std::size_t p = 0; p < n; ++p) {
        if (effect == "volumes") { out[p] = ComposeLayers::at(c.inscatter, p); continue; }
        if (!c.geometry(p)) continue;
        if (effect == "shadows") out[p] = c.direct(p);
        else if (effect == "reflections") out[p] = c.specular(p);
        else if (effect == "ao") out[p] = vec3(ao ? ao[p] : 1.f);
        else if (effect == "gi") out[p] = c.diffuseIndirect(p);
        else if (effect == "translucency") out[p] = c.transmitted(p);
        else throw std::invalid_argument("effectContribution: unknown effect '" + effect + "'");
    }
    return out;
}

FrameOutput renderFrame(const tracer::AccelManager& accel, const ecs::SceneSnapshot& scene, const FramePlan& plan,
                        const RenderSettings& settings) {
    FrameHistory none;
    return renderFrame(accel, scene, plan, settings, none);
}

FrameOutput renderFrame(const tracer::AccelManager& accel, const ecs::SceneSnapshot& scene, const FramePlan& plan,
                        const RenderSettings& settings, FrameHistory& history) {
    const FrameHistory& previous = history;
    if (settings.recordRayOrder && (!settings.backend || !settings.backend->orderDependent()))
        throw std::invalid_argument("renderFrame: recordRayOrder needs an order-dependent back end");
    FrameOutput out;
    out.image = Image(settings.width, settings.height);
    detail::RenderContext ctx(accel, scene, plan, settings);
    const auto run = [&](Pass pass, auto&& body) {
        const Stopwatch clock;
        tracer::TraceCounters counters;
        PassReport& report = out.passes[static_cast<std::size_t>(pass)];
        report.bytesAllocated = body(counters);
        report.rays = counters.totalRays();
        report.milliseconds = clock.elapsedMs();
        out.counters.add(counters);
    };
    // Step: the passes, in plan order.
    run(Pass::GBuffer, [&](tracer::TraceCounters& c) {
        return detail::runGBufferPass(ctx, previous, out.image, settings.recordRayOrder ? &out.primaryRayPixels : nullptr, c);
    });
    const std::size_t n = ctx.gbuffer.size();
    std::vector<vec3> direct(n, vec3(0.f)), irradiance(n, vec3(0.f)), specular(n, vec3(0.f)),
        transmitted(n, vec3(0.f)), inscatter(n, vec3(0.f));
    std::vector<float> primaryTransmittance(n, 1.f);
    if (plan.has(Pass::Shadows))
        run(Pass::Shadows, [&](tracer::TraceCounters& c) { return detail::runShadowPass(ctx, out.image, direct, c); });
    if (plan.has(Pass::Reflections))
        run(Pass::Reflections,
            [&](tracer::TraceCounters& c) { return detail::runReflectionPass(ctx, out.image, specular, c); });
    if (plan.has(Pass::Translucency))
        run(Pass::Translucency,
            [&](tracer::TraceCounters& c) { return detail::runTranslucencyPass(ctx, out.image, transmitted, c); });
    if (plan.has(Pass::AmbientOcclusion))
        run(Pass::AmbientOcclusion,
            [&](tracer::TraceCounters& c) { return detail::runAmbientOcclusionPass(ctx, out.image, c); });
    if (plan.has(Pass::GlobalIllumination))
        run(Pass::GlobalIllumination, [&](tracer::TraceCounters& c) {
            return plan.gi == GiTechnique::Ddgi
                       ? detail::runDdgiPass(ctx, history, out.image, irradiance, out.ddgiAtlas, out.ddgi, c)
                       : detail::runGlobalIlluminationPass(ctx, out.image, irradiance, c);
        });
    if (plan.has(Pass::Volumes) && !ctx.media.empty())
        run(Pass::Volumes, [&](tracer::TraceCounters& c) {
            return detail::runVolumePass(ctx, out.image, primaryTransmittance, inscatter, c);
        });
    if (plan.has(Pass::PathTrace))
        run(Pass::PathTrace,
            [&](tracer::TraceCounters& c) { return detail::runPathTracePass(ctx, out.image, out.pathVertices, c); });

    // Step: compose (from the layers, as after denoising).
    composeBeauty(out.image);
    // Step: nothing non-finite leaves a pass.
    for (const std::string& name : out.image.channelNames()) {
        float* c = out.image.channel(name);
        for (std::size_t i = 0; i < out.image.pixelCount(); ++i)
            if (!std::isfinite(c[i])) {
                c[i] = 0.f;
                ++out.nonFiniteValuesRepaired;
            }
    }
    history.record(scene);
    return out;
}

}  // namespace rtlab::shaders
