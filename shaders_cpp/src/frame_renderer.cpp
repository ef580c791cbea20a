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

void composeBeauty(Image& frame) {
    const std::size_t n = frame.pixelCount();
    const auto rgb = [&](const std::string& layer) -> std::vector<vec3> {
        return frame.hasChannel(layer.empty() ? "R" : layer + ".R") ? frame.rgbLayer(layer) : std::vector<vec3>();
    };
    const auto scalar = [&](const std::string& name) -> const float* { return frame.channel(name); };
    const std::vector<vec3> albedo = rgb("albedo"), emissive = rgb("emissive"), point = rgb("direct.point"),
                            gi = rgb("gi"), reflection = rgb("reflection"), brdf = rgb("reflection.brdf"),
                            translucency = rgb("translucency"), inscatter = rgb("volume.inscatter");
    const float* metalness = scalar("metalness.Y");
    const float* transmission = scalar("transmission.Y");
    const float* T = scalar("volume.transmittance");
    const float* mesh = scalar("id.mesh");
    std::vector<std::vector<vec3>> unshadowed;
    std::vector<const float*> visibility;
    for (int i = 0; frame.hasChannel("direct.light" + std::to_string(i) + ".R"); ++i) {
        unshadowed.push_back(rgb("direct.light" + std::to_string(i)));
        visibility.push_back(scalar("shadow.light" + std::to_string(i) + ".V"));
    }
    std::vector<vec3> beauty(n, vec3(0.f));
    for (std::size_t p = 0; p < n; ++p) {
        beauty[p] = inscatter.empty() ? vec3(0.f) : inscatter[p];
        if (!mesh || mesh[p] < 0.f) continue;
        vec3 direct(0.f);
        for (std::size_t l = 0; l < unshadowed.size(); ++l)
            direct += unshadowed[l][p] * (visibility[l] ? visibility[l][p] : 1.f);
        if (!point.empty()) direct += point[p];
        const float m = metalness ? metalness[p] : 0.f, t = transmission ? transmission[p] : 0.f;
        const vec3 a = albedo.empty() ? vec3(0.f) : albedo[p];
        const vec3 diffuseAlbedo = (1.f - m) * (1.f - t) * a;
        const vec3 e = emissive.empty() ? vec3(0.f) : emissive[p];
        const vec3 irradiance = gi.empty() ? vec3(0.f) : gi[p];
        const vec3 specular = brdf.empty() || reflection.empty() ? vec3(0.f) : brdf[p] * reflection[p];
        const vec3 transmitted = translucency.empty() ? vec3(0.f) : translucency[p];
        beauty[p] += (T ? T[p] : 1.f) * (e + direct + diffuseAlbedo * irradiance / kPi + specular + t * transmitted);
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
