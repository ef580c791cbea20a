// The effect table (effect_table.hpp): per pass, its name, what the planner
// checks, the pass function, its denoise stack and its layers.
#include <rtlab/shaders_cpp/effect_table.hpp>

#include "passes/passes.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

namespace rtlab::shaders {
namespace {

std::string plural(std::size_t n, const std::string& what) {
    return std::to_string(n) + " " + what + (n == 1 ? "" : "s");
}

std::size_t lightCount(const SceneFacts& f) { return f.areaLights + f.pointLights + f.directionalLights; }

// Step: what each pass needs, and whether the scene has it.
PlannedPass planGBuffer(const SceneFacts& f, const PlanOptions&) {
    return {Pass::GBuffer, true,
            f.instances ? plural(f.instances, "instance") + " visible to primary rays"
                        : "no geometry: primary rays all miss"};
}

PlannedPass planAlphaMask(const SceneFacts& f, const PlanOptions& options) {
    if (f.maskedMaterials > 0 && options.opaque)
        return {Pass::AlphaMask, false,
                "--opaque: " + plural(f.maskedMaterials, "alpha-masked material") +
                    " traced as opaque (cut-outs closed), no any-hit shader"};
    return {Pass::AlphaMask, f.maskedMaterials > 0,
            f.maskedMaterials ? plural(f.maskedMaterials, "alpha-masked material") +
                                    ": any-hit alpha test on every ray type (the masks are geometry: --effects "
                                    "keeps it, --opaque turns it off)"
                              : "no alpha-masked material: every ray is FORCE_OPAQUE, no any-hit shader"};
}

PlannedPass planShadows(const SceneFacts& f, const PlanOptions&) {
    std::string why;
    if (lightCount(f) == 0) {
        why = "no light";
    } else {
        std::vector<std::string> parts;
        if (f.areaLights) parts.push_back(plural(f.areaLights, "area light") + " (one visibility buffer each)");
        if (f.pointLights) parts.push_back(plural(f.pointLights, "point light") + " (one picked per pixel)");
        if (f.directionalLights) parts.push_back(plural(f.directionalLights, "directional light"));
        for (std::size_t i = 0; i < parts.size(); ++i) why += (i ? ", " : "") + parts[i];
    }
    return {Pass::Shadows, lightCount(f) > 0 && f.instances > 0, f.instances ? why : "no geometry to shadow"};
}

PlannedPass planReflections(const SceneFacts& f, const PlanOptions& options) {
    char threshold[32];
    std::snprintf(threshold, sizeof threshold, "%g", options.reflectionMaxRoughness);
    return {Pass::Reflections, f.glossyMaterials > 0,
            f.glossyMaterials ? plural(f.glossyMaterials, "material") + " with roughness <= " + threshold
                              : std::string("no opaque material with roughness <= ") + threshold};
}

PlannedPass planAmbientOcclusion(const SceneFacts& f, const PlanOptions&) {
    return {Pass::AmbientOcclusion, f.instances > 0,
            f.instances ? "geometry present: cosine-hemisphere occlusion rays" : "no geometry"};
}

PlannedPass planGlobalIllumination(const SceneFacts& f, const PlanOptions& options) {
    const bool lit = lightCount(f) + f.emissiveMaterials > 0;
    return {Pass::GlobalIllumination, lit && f.instances > 0,
            lit ? std::string(giTechniqueName(options.gi)) + ": " + plural(lightCount(f), "light") + ", " +
                      plural(f.emissiveMaterials, "emissive material")
                : "no light and no emissive material"};
}

PlannedPass planTranslucency(const SceneFacts& f, const PlanOptions&) {
    return {Pass::Translucency, f.transmissiveMaterials > 0,
            f.transmissiveMaterials ? plural(f.transmissiveMaterials, "transmissive material")
                                    : "no transmissive material"};
}

PlannedPass planVolumes(const SceneFacts& f, const PlanOptions&) {
    return {Pass::Volumes, f.volumes > 0,
            f.volumes ? plural(f.volumes, "volume") +
                            ": transmittance on primary, shadow, reflection and path-GI rays, single scattering"
                      : "no volume: OpenVDB code is not touched"};
}

// The path tracer is a ray workload for studies (the incoherent mix of
// multi-bounce paths), not part of the real-time frame: only on request.
PlannedPass planPathTrace(const SceneFacts& f, const PlanOptions& options) {
    const bool asked =
        std::find(options.requested.begin(), options.requested.end(), Pass::PathTrace) != options.requested.end();
    if (!asked) return {Pass::PathTrace, false, "a ray workload for studies: only with --effects pathtrace"};
    return {Pass::PathTrace, f.instances > 0,
            f.instances ? "asked for: diffuse + glossy paths with next-event estimation, " +
                              plural(lightCount(f), "light") + ", " + plural(f.emissiveMaterials, "emissive material")
                        : "no geometry"};
}

// Step: the rows, in execution order (the RT-core model is order-dependent:
// reordering passes changes its cycles).
constexpr std::array<EffectRow, kPassCount> kTable = {{
    {Pass::GBuffer, "gbuffer", false, "",
     "depth.Z, normal, albedo, emissive, roughness, metalness, transmission, id.mesh, motion, footprint.pixelWorld",
     planGBuffer, detail::runGBufferPass},
    {Pass::AlphaMask, "alpha", true, "", "(none: any-hit shaders on every ray type)", planAlphaMask, nullptr},
    {Pass::Shadows, "shadows", true, "shadow",
     "direct.light<i>, shadow.light<i>.V / .penumbra per area light; direct.point or direct.pointPicked", planShadows,
     detail::runShadowPass},
    {Pass::Reflections, "reflections", true, "reflection", "reflection, reflection.brdf, reflection.hitT",
     planReflections, detail::runReflectionPass},
    {Pass::Translucency, "translucency", true, "svgf", "translucency", planTranslucency, detail::runTranslucencyPass},
    {Pass::AmbientOcclusion, "ao", true, "ao", "ao.V, ao.hitT", planAmbientOcclusion, detail::runAmbientOcclusionPass},
    {Pass::GlobalIllumination, "gi", true, "svgf", "gi (irradiance, albedo demodulated)", planGlobalIllumination,
     detail::runDiffuseGiPass},
    {Pass::Volumes, "volumes", true, "svgf", "volume.inscatter, volume.transmittance", planVolumes,
     detail::runVolumePass},
    {Pass::PathTrace, "pathtrace", true, "", "pathtrace (the whole estimate)", planPathTrace, detail::runPathTracePass},
}};

bool keep(const EffectRow& row, EffectFilter filter) {
    switch (filter) {
        case EffectFilter::All: return true;
        case EffectFilter::Listable: return row.listable;
        case EffectFilter::Denoised: return !row.denoiseStack.empty();
    }
    return false;
}

}  // namespace

std::span<const EffectRow> effectTable() { return kTable; }

const EffectRow& effectRow(Pass pass) {
    for (const EffectRow& row : kTable)
        if (row.pass == pass) return row;
    throw std::logic_error("effectRow: a Pass without a row in the effect table");
}

const EffectRow* effectRowByName(std::string_view name) {
    for (const EffectRow& row : kTable)
        if (row.name == name) return &row;
    return nullptr;
}

std::string effectNames(EffectFilter filter, std::string_view separator) {
    std::string names;
    for (const EffectRow& row : kTable)
        if (keep(row, filter)) names += (names.empty() ? "" : std::string(separator)) + std::string(row.name);
    return names;
}

}  // namespace rtlab::shaders
