#include "commands.hpp"

#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/shaders_cpp/frame_plan.hpp>

#include <iostream>

namespace rtlab::app {

void addPlanCommand(CLI::App& app, PlanOptions& o) {
    CLI::App* cmd = app.add_subcommand("plan", "Print the passes a scene needs and why (DESIGN.md frame planner)");
    cmd->add_option("--scene", o.scene, "builtin:NAME, .gltf/.glb, or scene .json")->required();
    cmd->add_option("--effects", o.effects, "auto, or a comma-separated list of passes to keep")->capture_default_str();
    cmd->add_option("--gi", o.gi, "Diffuse GI technique")->check(CLI::IsMember({"path", "ddgi"}))->capture_default_str();
    cmd->add_flag("--json", o.json, "Print the plan as JSON");
}

shaders::PlanOptions planOptions(const std::string& effects, const std::string& gi) {
    shaders::PlanOptions options;
    options.requested = shaders::parseEffectList(effects);
    options.gi = gi == "ddgi" ? shaders::GiTechnique::Ddgi : shaders::GiTechnique::Path;
    return options;
}

int runPlan(const PlanOptions& o) {
    const shaders::PlanOptions options = planOptions(o.effects, o.gi);
    ecs::World world;
    loadSceneWithWarnings(world, o.scene);
    const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, world.update(0.f));
    const shaders::FramePlan plan = shaders::planFrame(scene, options);
    if (o.json) {
        nlohmann::json j = plan.toJson();
        j["sceneSource"] = o.scene;
        std::cout << j.dump(2) << "\n";
    } else {
        std::cout << "plan for " << o.scene << " (gi: " << shaders::giTechniqueName(plan.gi) << ")\n" << plan.toText();
    }
    return 0;
}

}  // namespace rtlab::app
