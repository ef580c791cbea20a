// renderFrame: the planned passes in order, then the composed beauty image.
#include "passes/passes.hpp"

#include <rtlab/shaders_cpp/effect_table.hpp>

#include <rtlab/core/parallel.hpp>
#include <rtlab/core/timer.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
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

void RenderSettings::validate() const {
    if (width < 1 || height < 1 || spp < 1 || maxTranslucencyDepth < 1 || pathMaxDepth < 0)
        throw std::invalid_argument(
            "RenderSettings: width, height, spp and maxTranslucencyDepth must be >= 1 and "
            "pathMaxDepth >= 0 (got " +
            std::to_string(width) + "x" + std::to_string(height) + ", spp " + std::to_string(spp) +
            ", maxTranslucencyDepth " + std::to_string(maxTranslucencyDepth) + ", pathMaxDepth " +
            std::to_string(pathMaxDepth) + ")");
}

std::string_view rayTypeName(std::uint32_t rayType) {
    static constexpr std::array<std::string_view, kRayTypeCount> kNames = {
        "primary", "shadow", "reflection", "ao", "gi", "translucency", "pathBounce"};
    return rayType < kRayTypeCount ? kNames[rayType] : std::string_view("unknown");
}

namespace {

// A frame's layers as the compose reads them, as planes (no copies); absent
// layers count as 0 (T as 1).
struct ComposeLayers {
    using Planes = std::array<const float*, 3>;
    Planes albedo, emissive, point, gi, reflection, brdf, translucency, inscatter, pathTraced;
    const float* metalness = nullptr;
    const float* transmission = nullptr;
    const float* transmittance = nullptr;
    const float* mesh = nullptr;
    std::vector<Planes> unshadowed;
    std::vector<const float*> visibility;

    explicit ComposeLayers(const Image& frame) {
        albedo = frame.rgbPlanes("albedo"), emissive = frame.rgbPlanes("emissive"), gi = frame.rgbPlanes("gi");
        // The point lights: traced one by one (direct.point) or picked per pixel (direct.pointPicked).
        point = frame.hasChannel("direct.pointPicked.R") ? frame.rgbPlanes("direct.pointPicked")
                                                         : frame.rgbPlanes("direct.point");
        reflection = frame.rgbPlanes("reflection"), brdf = frame.rgbPlanes("reflection.brdf");
        translucency = frame.rgbPlanes("translucency");
        inscatter = frame.rgbPlanes("volume.inscatter");
        pathTraced = frame.rgbPlanes("pathtrace");
        metalness = frame.channel("metalness.Y");
        transmission = frame.channel("transmission.Y");
        transmittance = frame.channel("volume.transmittance");
        mesh = frame.channel("id.mesh");
        for (int i = 0; frame.hasChannel("direct.light" + std::to_string(i) + ".R"); ++i) {
            unshadowed.push_back(frame.rgbPlanes("direct.light" + std::to_string(i)));
            visibility.push_back(frame.channel("shadow.light" + std::to_string(i) + ".V"));
        }
    }
    static bool has(const Planes& layer) { return layer[0] != nullptr; }
    static vec3 at(const Planes& layer, std::size_t p) {
        return has(layer) ? vec3(layer[0][p], layer[1][p], layer[2][p]) : vec3(0.f);
    }
    bool geometry(std::size_t p) const { return mesh && mesh[p] >= 0.f; }
    float transmissionAt(std::size_t p) const { return transmission ? transmission[p] : 0.f; }
    // Sum over area lights of unshadowed x visibility, plus the point lights.
    vec3 direct(std::size_t p) const {
        vec3 d(0.f);
        for (std::size_t l = 0; l < unshadowed.size(); ++l)
            d += at(unshadowed[l], p) * (visibility[l] ? visibility[l][p] : 1.f);
        if (has(point)) d += at(point, p);
        return d;
    }
    // (1 - metalness)(1 - transmission) albedo / pi x E.
    vec3 diffuseIndirect(std::size_t p) const {
        const float m = metalness ? metalness[p] : 0.f;
        return (1.f - m) * (1.f - transmissionAt(p)) * at(albedo, p) * at(gi, p) / kPi;
    }
    vec3 specular(std::size_t p) const {
        return has(brdf) && has(reflection) ? at(brdf, p) * at(reflection, p) : vec3(0.f);
    }
    vec3 transmitted(std::size_t p) const { return transmissionAt(p) * at(translucency, p); }
};

}  // namespace

void composeBeauty(Image& frame) {
    const std::size_t n = frame.pixelCount();
    // The beauty planes first (adding channels leaves the layers' planes in place).
    std::array<float*, 3> beauty = {frame.channel("R"), frame.channel("G"), frame.channel("B")};
    if (!beauty[0] || !beauty[1] || !beauty[2]) beauty = frame.addRgbPlanes("");
    const ComposeLayers c(frame);
    parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
        for (std::size_t p = begin; p < end; ++p) {
            vec3 b = ComposeLayers::at(c.inscatter, p);
            if (c.geometry(p)) {
                const float T = c.transmittance ? c.transmittance[p] : 1.f;
                if (ComposeLayers::has(c.pathTraced))
                    b += T * ComposeLayers::at(c.pathTraced, p);  // the path tracer's layer is the whole estimate
                else
                    b += T * (ComposeLayers::at(c.emissive, p) + c.direct(p) + c.diffuseIndirect(p) + c.specular(p) +
                              c.transmitted(p));
            }
            beauty[0][p] = b.x;
            beauty[1][p] = b.y;
            beauty[2][p] = b.z;
        }
    });
}

std::vector<vec3> effectContribution(const Image& frame, const std::string& effect) {
    static const std::array<std::string, 6> kEffects = {"volumes", "shadows", "reflections",
                                                        "ao",      "gi",      "translucency"};
    const auto which = std::find(kEffects.begin(), kEffects.end(), effect);
    if (which == kEffects.end()) throw std::invalid_argument("effectContribution: unknown effect '" + effect + "'");
    const std::size_t e = static_cast<std::size_t>(which - kEffects.begin());
    const std::size_t n = frame.pixelCount();
    const ComposeLayers c(frame);
    const float* ao = frame.channel("ao.V");
    std::vector<vec3> out(n, vec3(0.f));
    parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
        for (std::size_t p = begin; p < end; ++p) {
            if (e == 0) {
                out[p] = ComposeLayers::at(c.inscatter, p);
                continue;
            }
            if (!c.geometry(p)) continue;
            switch (e) {
                case 1: out[p] = c.direct(p); break;
                case 2: out[p] = c.specular(p); break;
                case 3: out[p] = vec3(ao ? ao[p] : 1.f); break;
                case 4: out[p] = c.diffuseIndirect(p); break;
                default: out[p] = c.transmitted(p); break;
            }
        }
    });
    return out;
}

FrameOutput renderFrame(const tracer::AccelManager& accel, const ecs::SceneSnapshot& scene, const FramePlan& plan,
                        const RenderSettings& settings) {
    FrameHistory none;
    return renderFrame(accel, scene, plan, settings, none);
}

FrameOutput renderFrame(const tracer::AccelManager& accel, const ecs::SceneSnapshot& scene, const FramePlan& plan,
                        const RenderSettings& settings, FrameHistory& history) {
    settings.validate();
    if (settings.recordRayOrder && !settings.backend)
        throw std::invalid_argument("renderFrame: recordRayOrder needs a back end");
    FrameOutput out;
    out.image = Image(settings.width, settings.height);
    detail::RenderContext ctx(accel, scene, plan, settings);
    detail::PassFrame frame{ctx, history, out};
    // Step: the planned passes, in the effect table's (execution) order.
    for (const EffectRow& row : effectTable()) {
        if (!row.run || !plan.has(row.pass)) continue;
        const Stopwatch clock;
        tracer::TraceCounters counters;
        PassReport& report = out.passes[static_cast<std::size_t>(row.pass)];
        // A pass is one launch over the frame's pixels: its dispatches (a
        // path's bounces, a light's shadow rays) are the same threads.
        tracer::LaunchScope launch(settings.backend, std::uint64_t(settings.width) * std::uint64_t(settings.height),
                                   row.name);
        report.bytesAllocated = row.run(frame, counters);
        launch.end();
        report.rays = counters.totalRays();
        report.milliseconds = clock.elapsedMs();
        out.counters.add(counters);
    }

    // Step: compose (from the layers, as after denoising).
    composeBeauty(out.image);
    // Step: nothing non-finite leaves a pass (counted per chunk, summed in order).
    const std::size_t pixels = out.image.pixelCount();
    for (const std::string& name : out.image.channelNames()) {
        float* c = out.image.channel(name);
        std::vector<std::uint64_t> repaired((pixels + kPixelChunk - 1) / kPixelChunk, 0);
        parallelForChunks(pixels, kPixelChunk, [&](std::size_t begin, std::size_t end) {
            std::uint64_t count = 0;
            for (std::size_t i = begin; i < end; ++i) {
                // Exponent bits all ones: Inf or NaN (a branch-free test that vectorises).
                const bool nonFinite = (std::bit_cast<std::uint32_t>(c[i]) & 0x7f800000u) == 0x7f800000u;
                count += nonFinite;
                c[i] = nonFinite ? 0.f : c[i];
            }
            repaired[begin / kPixelChunk] = count;
        });
        for (const std::uint64_t r : repaired) out.nonFiniteValuesRepaired += r;
    }
    history.record(scene);
    return out;
}

}  // namespace rtlab::shaders
