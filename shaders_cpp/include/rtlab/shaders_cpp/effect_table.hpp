#pragma once
// The effect table: one row per pass (DESIGN.md, "one table of effects"),
// in execution order. The planner asks each row whether the scene has its
// inputs, the renderer runs each planned row's pass, and `--effects`,
// `--denoise`, `rtlab converge --effect` and their help texts take their
// names from it. The denoise module (which sees images, never the scene)
// keys its per-layer stacks by the same names (denoise/src/effect_layers.cpp);
// tests/shaders_cpp/test_effect_table.cpp holds the two together.
//
// Adding an effect: a Pass value (frame_plan.hpp), a row here
// (src/effect_table.cpp), its pass file (src/passes/), and, when it is
// denoised, its layers in denoise/src/effect_layers.cpp (docs/architecture.md).
#include <rtlab/shaders_cpp/frame_plan.hpp>
#include <rtlab/tracer/pipeline.hpp>

#include <cstdint>
#include <span>
#include <string>
#include <string_view>

namespace rtlab::shaders {

namespace detail {
struct PassFrame;  // the frame's shared state as the passes see it (src/passes/passes.hpp)
}

struct EffectRow {
    Pass pass = Pass::GBuffer;
    std::string_view name;          // in --effects, stats.json and the plan
    bool listable = true;           // may be named in --effects (the G-buffer is always planned)
    std::string_view denoiseStack;  // the stack that filters its layers (denoise::stackName); "" = not denoised
    std::string_view layers;        // the image layers it writes (docs/effects.md)
    // Whether the scene gives the pass its inputs, and why (or why not).
    PlannedPass (*plan)(const SceneFacts& facts, const PlanOptions& options) = nullptr;
    // The pass; it returns the bytes it allocated. nullptr: no pass of its
    // own (the alpha test is any-hit shaders on every ray type).
    std::uint64_t (*run)(detail::PassFrame& frame, tracer::TraceCounters& counters) = nullptr;
};

// Every row, in execution order.
std::span<const EffectRow> effectTable();
const EffectRow& effectRow(Pass pass);
const EffectRow* effectRowByName(std::string_view name);

enum class EffectFilter { All, Listable, Denoised };
// The names of the rows that pass the filter, joined by `separator` (help texts, error messages).
std::string effectNames(EffectFilter filter, std::string_view separator = ",");

}  // namespace rtlab::shaders
