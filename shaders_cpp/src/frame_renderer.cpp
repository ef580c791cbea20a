// renderFrame: the planned passes in order, then the composed beauty image.
#include "render_context.hpp"

#include <rtlab/core/timer.hpp>

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
                       ? detail::runDdgiPass(ctx, history, out.image, irradiance, out.ddgiAtlas, c)
                       : detail::runGlobalIlluminationPass(ctx, out.image, irradiance, c);
        });
    if (plan.has(Pass::Volumes) && !ctx.media.empty())
        run(Pass::Volumes, [&](tracer::TraceCounters& c) {
            return detail::runVolumePass(ctx, out.image, primaryTransmittance, inscatter, c);
        });
    // Any-hit calls belong to the alpha pass: it has no rays of its own.
    out.passes[static_cast<std::size_t>(Pass::AlphaMask)].rays = 0;

    // Step: compose = in-scattered + T x (emission + direct + diffuse x irradiance / pi
    //                 + specular x reflected radiance + transmission x translucency).
    std::vector<vec3> beauty(n, vec3(0.f));
    for (std::size_t i = 0; i < n; ++i) {
        const detail::GPixel& g = ctx.gbuffer[i];
        beauty[i] = inscatter[i];
        if (!g.hit) continue;
        const vec3 diffuseAlbedo = (1.f - g.metalness) * (1.f - g.transmission) * g.albedo;
        beauty[i] += primaryTransmittance[i] * (g.emissive + direct[i] + diffuseAlbedo * irradiance[i] / kPi +
                                                specular[i] + g.transmission * transmitted[i]);
    }
    out.image.addRgbLayer("", beauty);
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
