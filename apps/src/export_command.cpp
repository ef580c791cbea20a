// rtlab export: any scene's triangles and materials as OBJ + MTL or PLY, in
// world space at its first frame (docs/scene-format.md, "Export"), so that
// other tools run the very same workloads.
#include "commands.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/ecs/save/scene_writer.hpp>
#include <rtlab/session/frame_session.hpp>

#include <algorithm>
#include <cctype>
#include <iostream>

namespace rtlab::app {

void addExportCommand(CLI::App& app, ExportOptions& o) {
    CLI::App* cmd = app.add_subcommand("export", "Write a scene's triangles and materials as OBJ + MTL or PLY");
    cmd->add_option("--scene", o.scene, "builtin:NAME[?k=v&...], .gltf/.glb, .obj, or scene .json")->required();
    cmd->add_option("--out", o.out, "FILE.obj (with FILE.mtl beside it) or FILE.ply")->required();
}

int runExport(const ExportOptions& o) {
    std::string ext = std::filesystem::path(o.out).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    if (ext != ".obj" && ext != ".ply") throw InputError(o.out, "--out must end in .obj or .ply");
    const std::filesystem::path dir = std::filesystem::path(o.out).parent_path();
    std::error_code ec;
    if (!dir.empty() && !std::filesystem::is_directory(dir, ec))
        throw InputError(o.out, "the directory " + dir.string() + " does not exist");
    session::FrameOptions options;
    options.scene = o.scene;
    session::FrameSession s(options, session::Stages::Plan);
    s.load();
    const ecs::save::ExportStats st =
        ext == ".obj" ? ecs::save::writeObj(s.world(), o.out) : ecs::save::writePly(s.world(), o.out);
    std::cerr << "rtlab: exported " << st.triangles << " triangles, " << st.vertices << " vertices, " << st.materials
              << " materials to " << o.out;
    if (st.proceduralGeometriesLeftOut)
        std::cerr << " (" << st.proceduralGeometriesLeftOut << " procedural geometries left out)";
    std::cerr << "\n";
    return 0;
}

}  // namespace rtlab::app
