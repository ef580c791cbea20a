#include <rtlab/shaders_cpp/frame_plan.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/shaders_cpp/effect_table.hpp>

#include <algorithm>
#include <set>
#include <sstream>

namespace rtlab::shaders {

std::string_view passName(Pass pass) { return effectRow(pass).name; }

std::optional<Pass> passFromName(std::string_view name) {
    const EffectRow* row = effectRowByName(name);
    return row ? std::optional<Pass>(row->pass) : std::nullopt;
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
    plan.facts = sceneFacts(scene, options.reflectionMaxRoughness);
    // Step: each row's check: does the scene give the pass its inputs?
    for (const EffectRow& row : effectTable())
        plan.passes[static_cast<std::size_t>(row.pass)] = row.plan(plan.facts, options);

    // Step: --effects narrows the plan, never forces a pass without its
    // inputs, and never changes geometry as rays see it (the alpha test stays).
    if (!options.requested.empty()) {
        for (std::size_t i = 0; i < kPassCount; ++i) {
            const Pass p = static_cast<Pass>(i);
            if (p == Pass::GBuffer || p == Pass::AlphaMask) continue;
            const bool asked =
                std::find(options.requested.begin(), options.requested.end(), p) != options.requested.end();
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
            throw InputError("--effects", "unknown effect '" + item + "' (known: auto, " +
                                              effectNames(EffectFilter::All, ", ") + ")");
        }
        if (std::find(passes.begin(), passes.end(), *p) == passes.end()) passes.push_back(*p);
    }
    if (passes.empty()) throw InputError("--effects", "empty effect list (use auto or names)");
    return passes;
}

}  // namespace rtlab::shaders
