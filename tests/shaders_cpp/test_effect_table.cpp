// The effect table: one row per pass, the names every command uses, and
// the denoise module's per-layer stacks keyed by the same rows.
#include "shaders_cpp/static_view.hpp"

#include <rtlab/denoise/effect_layers.hpp>
#include <rtlab/shaders_cpp/effect_table.hpp>
#include <rtlab/shaders_cpp/frame_renderer.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <set>

namespace rtlab::shaders {
namespace {

TEST(EffectTable, OneRowPerPassNamedAsTheCommandsNameIt) {
    std::set<Pass> passes;
    std::set<std::string_view> names;
    for (const EffectRow& row : effectTable()) {
        EXPECT_TRUE(passes.insert(row.pass).second) << row.name;
        EXPECT_TRUE(names.insert(row.name).second) << row.name;
        EXPECT_NE(row.plan, nullptr) << row.name;
        EXPECT_FALSE(row.layers.empty()) << row.name;
        EXPECT_EQ(passName(row.pass), row.name);
        EXPECT_EQ(passFromName(row.name), row.pass);
        EXPECT_EQ(&effectRow(row.pass), &row);
        EXPECT_EQ(effectRowByName(row.name), &row);
    }
    EXPECT_EQ(passes.size(), kPassCount);
    EXPECT_EQ(effectTable().front().pass, Pass::GBuffer);  // every other pass reads the G-buffer
    EXPECT_FALSE(effectRow(Pass::GBuffer).listable);
    EXPECT_EQ(effectRow(Pass::AlphaMask).run, nullptr);  // any-hit shaders, no pass of its own
    EXPECT_EQ(effectNames(EffectFilter::Denoised), "shadows,reflections,translucency,ao,gi,volumes");
}

TEST(EffectTable, DenoisedRowsAreTheDenoisersEffects) {
    std::vector<std::string> table;
    for (const EffectRow& row : effectTable())
        if (!row.denoiseStack.empty()) table.emplace_back(row.name);
    std::vector<std::string> denoiser = denoise::EffectLayerDenoiser::effectNames();
    std::sort(table.begin(), table.end());
    std::sort(denoiser.begin(), denoiser.end());
    EXPECT_EQ(table, denoiser);
}

// Each denoised row's stack is the one the denoise module runs on its
// layers, on a frame of showcase (which plans every effect but the path tracer).
TEST(EffectTable, EachRowsStackFiltersItsLayers) {
    const test::StaticView view("builtin:showcase");
    const FramePlan plan = planFrame(view.scene);
    RenderSettings settings;
    settings.width = 32;
    settings.height = 18;
    const Image frame = renderFrame(view.accel, view.scene, plan, settings).image;
    for (const EffectRow& row : effectTable()) {
        if (row.denoiseStack.empty()) continue;
        ASSERT_TRUE(plan.has(row.pass)) << row.name;
        Image copy = frame;
        std::set<std::string> stacks;
        for (const denoise::DenoisedLayer& l : denoise::EffectLayerDenoiser({std::string(row.name)}).apply(copy))
            stacks.insert(denoise::stackName(l.stack));
        EXPECT_TRUE(stacks.count(std::string(row.denoiseStack))) << row.name;
        // rtlab converge measures the row's term of the compose.
        EXPECT_NO_THROW(effectContribution(frame, std::string(row.name))) << row.name;
    }
}

}  // namespace
}  // namespace rtlab::shaders
