#include <rtlab/shaders_cpp/frame_plan.hpp>

#include <rtlab/core/error.hpp>

#include <algorithm>
#include <set>
#include <sstream>

namespace rtlab::shaders {
namespace {

constexpr std::array<std::string_view, kPassCount> kNames = {"gbuffer", "alpha",        "shadows",
                                                              "reflections", "ao", "gi",
                                                              "translucency", "volumes", "pathtrace"};

std::string plural(std::size_t n, const std::string& what) {
    return std::to_string(n) + " " + what + (n == 1 ? "" : "s");
}

}  // namespace

std::string_view passName(Pass pass) { return kNames[static_cast<std::size_t>(pass)]; }

std::optional<Pass> passFromName(std::string_view name) {
    for (std::size_t i = 0; i < kPassCount; ++i)
        if (kNames[i] == name) return static_cast<Pass>(i);
    return std::nullopt;
}

std::string_view giTechniqueName(GiTechnique technique) { return technique == GiTechnique::Ddgi ? "ddgi" : "path"; }

SceneFacts sceneFacts(const ecs::SceneSnapshot& scene, float reflectionMaxRoughness) {
    SceneFacts f;
    f.instances = scene.instances.size();
    // Step: materials that some instance actually uses.
    std::set<std::uint32_t> used;
    for (const ecs::InstanceSnapshot& inst : scene.instances)
        for (const ecs::Geometry& g : (*scene.meshes)[inst.mesh].geometries) used.insert(g.material);
    for (std::uint32_t id : used) {
        if (!scene.materials || id >= scene.materials->size()) continue;
        const ecs::Material& m = (*scene.materials)[id];
        f.maskedMaterials += m.alphaMode == ecs::AlphaMode::Mask;
        f.glossyMaterials += m.roughness <= reflectionMaxRoughness && m.transmission <= 0.f;
        f.transmissiveMaterials += m.transmission > 0.f;
        f.emissiveMaterials += glm::length(m.emissive) > 0.f;
    }
    // Step: lights that emit.
    for (const ecs::LightSnapshot& l : scene.lights) {
        if (!(l.light.intensity > 0.f) || !(glm::length(l.light.color) > 0.f)) continue;
        if (l.light.isArea()) ++f.areaLights;
        else if (l.light.type == ecs::LightType::Directional) ++f.directionalLights;
        else ++f.pointLights;
    }
    for (const ecs::VolumeSnapshot& v : scene.volumes) f.volumes += v.grid != nullptr && v.volume.densityScale > 0.f;
    return f;
}

FramePlan planFrame(const ecs::SceneSnapshot& scene, const PlanOptions& options) {
    FramePlan plan;
    plan.gi = options.gi;
    plan.reflectionMaxRoughness = options.reflectionMaxRoughness;
    const SceneFacts f = sceneFacts(scene, options.reflectionMaxRoughness);
    plan.facts = f;
    const std::size_t lights = f.areaLights + f.pointLights + f.directionalLights;
    char threshold[32];
    std::snprintf(threshold, sizeof threshold, "%g", options.reflectionMaxRoughness);

    // Step: what each pass needs, and whether the scene has it.
    const auto set = [&](Pass p, bool inputs, std::string why) {
        plan.passes[static_cast<std::size_t>(p)] = PlannedPass{p, inputs, std::move(why)};
    };
    set(Pass::GBuffer, true, f.instances ? plural(f.instances, "instance") + " visible to primary rays"
                                         : "no geometry: primary rays all miss");
    set(Pass::AlphaMask, f.maskedMaterials > 0,
        f.maskedMaterials ? plural(f.maskedMaterials, "alpha-masked material") + ": any-hit alpha test on every ray type"
                          : "no alpha-masked material: every ray is FORCE_OPAQUE, no any-hit shader");
    {
        std::string why;
        if (lights == 0) why = "no light";
        else {
            std::vector<std::string> parts;
            if (f.areaLights) parts.push_back(plural(f.areaLights, "area light") + " (one visibility buffer each)");
            if (f.pointLights) parts.push_back(plural(f.pointLights, "point light") + " (one picked per pixel)");
            if (f.directionalLights) parts.push_back(plural(f.directionalLights, "directional light"));
            for (std::size_t i = 0; i < parts.size(); ++i) why += (i ? ", " : "") + parts[i];
        }
        set(Pass::Shadows, lights > 0 && f.instances > 0, f.instances ? why : "no geometry to shadow");
    }
    set(Pass::Reflections, f.glossyMaterials > 0,
        f.glossyMaterials ? plural(f.glossyMaterials, "material") + " with roughness <= " + threshold
                          : std::string("no opaque material with roughness <= ") + threshold);
    set(Pass::AmbientOcclusion, f.instances > 0,
        f.instances ? "geometry present: cosine-hemisphere occlusion rays" : "no geometry");
    const bool lit = lights + f.emissiveMaterials > 0;
    set(Pass::GlobalIllumination, lit && f.instances > 0,
        lit ? std::string(giTechniqueName(options.gi)) + ": " + plural(lights, "light") + ", " +
                  plural(f.emissiveMaterials, "emissive material")
            : "no light and no emissive material");
    set(Pass::Translucency, f.transmissiveMaterials > 0,
        f.transmissiveMaterials ? plural(f.transmissiveMaterials, "transmissive material")
                                : "no transmissive material");
    set(Pass::Volumes, f.volumes > 0,
        f.volumes ? plural(f.volumes, "volume") + ": transmittance on primary, shadow, reflection and path-GI rays, single scattering"
                  : "no volume: OpenVDB code is not touched");
    // The path tracer is a ray workload for studies (the incoherent mix of
    // multi-bounce paths), not part of the real-time frame: only on request.
    const bool pathTraceAsked = std::find(options.requested.begin(), options.requested.end(), Pass::PathTrace) !=
                                options.requested.end();
    if (!pathTraceAsked)
        set(Pass::PathTrace, false, "a ray workload for studies: only with --effects pathtrace");
    else
        set(Pass::PathTrace, f.instances > 0,
            f.instances ? "asked for: diffuse + glossy paths with next-event estimation, " + plural(lights, "light") +
                              ", " + plural(f.emissiveMaterials, "emissive material")
                        : "no geometry");

    // Step: --effects narrows the plan, never forces a pass without its inputs.
    if (!options.requested.empty()) {
        for (std::size_t i = 0; i < kPassCount; ++i) {
            const Pass p = static_cast<Pass>(i);
            if (p == Pass::GBuffer) continue;
            const bool asked = std::find(options.requested.begin(), options.requested.end(), p) !=
                               options.requested.end();
            PlannedPass& pp = plan.passes[i];
            if (asked && !pp.planned)
                plan.notes.push_back(std::string(passName(p)) + " requested but not planned: " + pp.reason);
            if (!asked && pp.planned) {
                pp.planned = false;
                pp.reason = "left out by --effects (" + pp.reason + ")";
            }
        }
    }
    return plan;
}

nlohmann::json FramePlan::toJson() const {
    nlohmann::json j;
    j["gi"] = giTechniqueName(gi);
    j["reflectionMaxRoughness"] = reflectionMaxRoughness;
    j["passes"] = nlohmann::json::array();
    for (const PlannedPass& p : passes)
        j["passes"].push_back({{"pass", passName(p.pass)}, {"planned", p.planned}, {"reason", p.reason}});
    j["notes"] = notes;
    j["scene"] = {{"instances", facts.instances},
                  {"maskedMaterials", facts.maskedMaterials},
                  {"glossyMaterials", facts.glossyMaterials},
                  {"transmissiveMaterials", facts.transmissiveMaterials},
                  {"emissiveMaterials", facts.emissiveMaterials},
                  {"areaLights", facts.areaLights},
                  {"pointLights", facts.pointLights},
                  {"directionalLights", facts.directionalLights},
                  {"volumes", facts.volumes}};
    return j;
}

std::string FramePlan::toText() const {
    std::ostringstream out;
    for (const PlannedPass& p : passes)
        out << "  [" << (p.planned ? 'x' : ' ') << "] " << passName(p.pass) << ": " << p.reason << "\n";
    for (const std::string& n : notes) out << "  note: " << n << "\n";
    return out.str();
}

std::vector<Pass> parseEffectList(const std::string& list) {
    std::vector<Pass> passes;
    if (list.empty() || list == "auto") return passes;
    std::stringstream in(list);
    std::string item;
    while (std::getline(in, item, ',')) {
        if (item.empty()) continue;
        const std::optional<Pass> p = passFromName(item);
        if (!p) {
            std::string known;
            for (std::string_view n : kNames) known += (known.empty() ? "" : ", ") + std::string(n);
            throw InputError("--effects", "unknown effect '" + item + "' (known: auto, " + known + ")");
        }
        if (std::find(passes.begin(), passes.end(), *p) == passes.end()) passes.push_back(*p);
    }
    if (passes.empty()) throw InputError("--effects", "empty effect list (use auto or names)");
    return passes;
}

}  // namespace rtlab::shaders
