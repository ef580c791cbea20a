#pragma once
// The frame planner (DESIGN.md, "Leave out what a scene does not need"): the
// passes a frame runs are derived from the scene, each with the reason it
// runs or is left out. No glossy surface -> no reflection rays or buffers;
// no area light -> no per-light shadow buffers; no alpha-masked material ->
// no any-hit shaders (every ray FORCE_OPAQUE); no volume -> the volume code
// is never touched; no transmissive material -> no translucency pass.
// `--effects LIST` narrows the automatic plan; it never forces a pass whose
// inputs are absent (the plan says why it was refused).
#include <rtlab/ecs/snapshot.hpp>

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace rtlab::shaders {

// Every pass the renderer knows, in execution order.
enum class Pass : std::uint8_t {
    GBuffer,             // primary visibility and the guide buffers
    AlphaMask,           // any-hit alpha test on masked materials (all ray types)
    Shadows,             // direct light: per-area-light visibility, importance-sampled point lights
    Reflections,         // glossy/mirror reflections below the roughness threshold
    AmbientOcclusion,    // cosine-hemisphere visibility within a radius
    GlobalIllumination,  // one-bounce diffuse GI (path) or DDGI probes
    Translucency,        // refraction through transmissive materials
    Volumes,             // fog: transmittance on every ray + single scattering
    PathTrace,           // multi-bounce diffuse + glossy paths with next-event estimation (only when asked for)
};
inline constexpr std::size_t kPassCount = 9;
std::string_view passName(
    Pass pass);  // "gbuffer", "alpha", "shadows", "reflections", "ao", "gi", "translucency", "volumes", "pathtrace"
std::optional<Pass> passFromName(std::string_view name);

enum class GiTechnique : std::uint8_t { Path, Ddgi };
std::string_view giTechniqueName(GiTechnique technique);

struct PlanOptions {
    // Passes the user asked for (--effects LIST); empty = every pass the scene needs (auto).
    std::vector<Pass> requested;
    GiTechnique gi = GiTechnique::Path;
    float reflectionMaxRoughness = 0.3f;  // reflections trace only where roughness <= this
    // Alpha masks are the geometry's shape: `requested` never leaves the alpha
    // test out; only this does (--opaque: masked materials traced as opaque).
    bool opaque = false;
};

struct PlannedPass {
    Pass pass = Pass::GBuffer;
    bool planned = false;
    std::string reason;  // why it runs, or why not
};

// What the scene offers the passes, counted once.
struct SceneFacts {
    std::size_t instances = 0;
    std::size_t maskedMaterials = 0;  // used by some instance
    std::size_t glossyMaterials = 0;  // roughness <= reflectionMaxRoughness, used by some instance
    std::size_t transmissiveMaterials = 0;
    std::size_t emissiveMaterials = 0;
    std::size_t areaLights = 0;   // rect + sphere
    std::size_t pointLights = 0;  // point + spot
    std::size_t directionalLights = 0;
    std::size_t volumes = 0;
};
SceneFacts sceneFacts(const ecs::SceneSnapshot& scene, float reflectionMaxRoughness);

struct FramePlan {
    std::array<PlannedPass, kPassCount> passes;
    GiTechnique gi = GiTechnique::Path;
    float reflectionMaxRoughness = 0.3f;
    SceneFacts facts;
    std::vector<std::string> notes;  // requested passes refused, with the reason

    bool has(Pass pass) const { return passes[static_cast<std::size_t>(pass)].planned; }
    const PlannedPass& operator[](Pass pass) const { return passes[static_cast<std::size_t>(pass)]; }
    nlohmann::json toJson() const;
    std::string toText() const;  // one line per pass: "  [x] shadows: 1 rect light ..."
};

FramePlan planFrame(const ecs::SceneSnapshot& scene, const PlanOptions& options = {});

// Parses --effects: "auto" (empty list) or a comma-separated list of pass
// names ("gbuffer" is always planned and may be omitted). Throws InputError
// naming the unknown entry.
std::vector<Pass> parseEffectList(const std::string& list);

}  // namespace rtlab::shaders
