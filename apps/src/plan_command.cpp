// rtlab plan: the passes a scene needs and why (DESIGN.md, frame planner).
#include "commands.hpp"

#include <rtlab/session/frame_session.hpp>

#include <iostream>

namespace rtlab::app {

void addPlanCommand(CLI::App& app, PlanOptions& o) {
    CLI::App* cmd = app.add_subcommand("plan", "Print the passes a scene needs and why (DESIGN.md frame planner)");
    addFrameOptions(*cmd, o.frame, session::kUsePlan, true);
    cmd->add_flag("--json", o.json, "Print the plan as JSON");
}

int runPlan(const PlanOptions& o) {
    session::FrameSession s(o.frame, session::Stages::Plan);
    s.load();
    const shaders::FramePlan& plan = s.advance().plan;
    if (o.json) {
        nlohmann::json j = plan.toJson();
        j["sceneSource"] = o.frame.scene;
        std::cout << jsonText(j) << "\n";
    } else {
        std::cout << "plan for " << o.frame.scene << " (gi: " << shaders::giTechniqueName(plan.gi) << ")\n"
                  << plan.toText();
    }
    return 0;
}

}  // namespace rtlab::app
