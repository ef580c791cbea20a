// The GPU check's CPU side end to end (docs/validation.md): `rtlab
// gpucheck-export` of recordings on the builtin workloads and on a real
// third-party glTF, replayed by the host twin of the CUDA kernel
// (gpucheck-host: the same traversal code), which must give every ray's hit,
// traversal counters, fetched bytes, sectors and fetch checksum exactly as
// the model; a changed expectation is found (exit 1), damaged or foreign
// input exits 2 with one line; the model's sector metric is consistent.
#include "cli_test_util.hpp"

#include <gpucheck/format.hpp>

#include <cstring>

using namespace rtlab::test;

namespace {

const std::string kHost = std::string(RTLAB_BINARY_DIR) + "/gpucheck/gpucheck-host";
const std::string kEngine = "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";

struct Export {
    fs::path dir;
    nlohmann::json model;
};

// Records `effects` of `scene` on the model and exports the rays of `types`.
Export recordAndExport(const std::string& name, const std::string& scene, const std::string& effects,
                       const std::string& types, const std::string& extra = "") {
    const fs::path dir = freshDir("gpucheck_" + name);
    const CliRun render = runCli("render --scene '" + scene + "' --width 40 --height 24 --frames 1 --effects " +
                                 effects + " --denoise none --backend rtcore --record-rays " + (dir / "rec").string() +
                                 " --out " + (dir / "render").string());
    EXPECT_EQ(render.exitCode, 0) << render.out;
    const CliRun exported =
        runCli("gpucheck-export --scene '" + scene + "' --rays " + (dir / "rec" / "frame_0000.rays").string() +
               " --ray-types " + types + " --label " + name + " --out " + (dir / "export").string() + " " + extra);
    EXPECT_EQ(exported.exitCode, 0) << exported.out;
    std::ifstream in(dir / "export" / "model.json");
    return {dir / "export", nlohmann::json::parse(in)};
}

void expectHostTwinAgrees(const Export& e) {
    const CliRun host = runCommand(kHost + " " + e.dir.string());
    EXPECT_EQ(host.exitCode, 0) << host.out;
    EXPECT_NE(host.out.find(" 0 differ from the model"), std::string::npos) << host.out;
    EXPECT_GT(e.model["rays"].get<std::uint64_t>(), 0u);
}

}  // namespace

TEST(GpuCheck, HostTwinTraversesAsTheModelOnEveryWorkload) {
    // Primary, AO, shadow and path-bounce rays; one instance, 40 instances,
    // slivers, and a third-party glTF with its node hierarchy.
    expectHostTwinAgrees(recordAndExport("terrain_ao", "builtin:terrain?triangles=20000", "ao", "primary,ao"));
    // A path's next-event shadow rays end at their first hit (policy firstHit).
    const Export forest =
        recordAndExport("forest_path", "builtin:forest?instances=40", "pathtrace", "pathBounce,shadow");
    expectHostTwinAgrees(forest);
    EXPECT_GT(forest.model["policies"]["commitAll"].get<std::uint64_t>(), 0u);
    EXPECT_GT(forest.model["policies"]["firstHit"].get<std::uint64_t>(), 0u);
    expectHostTwinAgrees(recordAndExport("slivers_shadow", "builtin:slivers?triangles=20000", "shadows", "shadow"));
    expectHostTwinAgrees(recordAndExport("engine_primary", kEngine, "gbuffer", "primary"));
}

TEST(GpuCheck, SectorMetricCountsEveryFetchedSector) {
    // h100-like's sectored L1 (128-byte lines of 32-byte sectors) looks up
    // exactly the sectors each fetch touches (docs/validation.md, "Counting
    // the same thing"), every L1 miss is an L2 access, every L2 miss a 64-byte read.
    const Export e = recordAndExport("sectors", "builtin:terrain?triangles=20000", "gbuffer", "primary",
                                     "--rtcore-config h100-like");
    const nlohmann::json& p = e.model["predicted"];
    EXPECT_EQ(e.model["config"]["cache"]["sectorBytes"], 32);
    EXPECT_EQ(p["l1"]["accesses"], e.model["fetch"]["sectors"]);
    EXPECT_EQ(p["l2"]["accesses"], p["l1"]["misses"]);
    EXPECT_EQ(p["dram"]["readBytes"].get<std::uint64_t>(), 64u * p["l2"]["misses"].get<std::uint64_t>());
    EXPECT_GT(p["l1"]["hitRate"].get<double>(), 0.0);
    EXPECT_LT(p["l1"]["hitRate"].get<double>(), 1.0);
    // --max-rays keeps the first rays and says how many it left out.
    const Export few =
        recordAndExport("few", "builtin:terrain?triangles=20000", "gbuffer", "primary", "--max-rays 100");
    EXPECT_EQ(few.model["rays"], 100);
    EXPECT_EQ(few.model["left out"]["beyondMaxRays"], 40 * 24 - 100);
    expectHostTwinAgrees(few);
}

TEST(GpuCheck, ChangedOrDamagedInputIsFound) {
    const Export e = recordAndExport("damage", "builtin:terrain?triangles=5000", "ao", "ao");
    // One changed expected counter: exit 1, the ray named.
    {
        std::fstream f(e.dir / "expected.bin", std::ios::in | std::ios::out | std::ios::binary);
        const std::streamoff nodeVisits = sizeof(gpucheck::ExpectedHeader) + offsetof(gpucheck::RayOut, nodeVisits);
        std::uint32_t v = 0;
        f.seekg(nodeVisits);
        f.read(reinterpret_cast<char*>(&v), 4);
        ++v;
        f.seekp(nodeVisits);
        f.write(reinterpret_cast<const char*>(&v), 4);
    }
    const CliRun changed = runCommand(kHost + " " + e.dir.string());
    EXPECT_EQ(changed.exitCode, 1) << changed.out;
    EXPECT_NE(changed.out.find("ray 0 differs"), std::string::npos) << changed.out;
    // A reference out of the image (the TLAS root): exit 2, the ray named, no crash.
    {
        std::fstream f(e.dir / "scene.bin", std::ios::in | std::ios::out | std::ios::binary);
        const std::uint32_t farNode = 0x7ffffffu;
        f.seekp(offsetof(gpucheck::SceneHeader, tlasRoot));
        f.write(reinterpret_cast<const char*>(&farNode), 4);
    }
    const CliRun corrupt = runCommand(kHost + " " + e.dir.string());
    EXPECT_EQ(corrupt.exitCode, 2) << corrupt.out;
    EXPECT_NE(corrupt.out.find("corrupt memory image"), std::string::npos) << corrupt.out;
    // A truncated scene: exit 2 naming the file.
    fs::resize_file(e.dir / "scene.bin", fs::file_size(e.dir / "scene.bin") - 4);
    const CliRun truncated = runCommand(kHost + " " + e.dir.string());
    EXPECT_EQ(truncated.exitCode, 2) << truncated.out;
    EXPECT_NE(truncated.out.find("scene.bin"), std::string::npos) << truncated.out;
    EXPECT_EQ(runCommand(kHost + " " + (e.dir / "nothing").string()).exitCode, 2);
}

TEST(GpuCheck, ExportRefusesWhatItCannotCheck) {
    const fs::path dir = freshDir("gpucheck_refuse");
    const std::string scene = "'builtin:terrain?triangles=2000'";
    // Recorded on Embree: no verdicts to classify.
    ASSERT_EQ(runCli("render --scene " + scene +
                     " --width 16 --height 16 --frames 1 --effects ao --denoise none "
                     "--record-rays " +
                     (dir / "embree").string() + " --out " + (dir / "r1").string())
                  .exitCode,
              0);
    const CliRun embree = runCli("gpucheck-export --scene " + scene + " --rays " +
                                 (dir / "embree" / "frame_0000.rays").string() + " --out " + (dir / "x").string());
    EXPECT_EQ(embree.exitCode, 2) << embree.out;
    EXPECT_NE(embree.out.find("carries no candidate verdicts"), std::string::npos) << embree.out;
    EXPECT_FALSE(fs::exists(dir / "x" / "scene.bin"));
    // The model's recording on another scene; an unknown ray type; Embree as back end.
    ASSERT_EQ(runCli("render --scene " + scene +
                     " --width 16 --height 16 --frames 1 --effects ao --denoise none "
                     "--backend rtcore --record-rays " +
                     (dir / "model").string() + " --out " + (dir / "r2").string())
                  .exitCode,
              0);
    const std::string rays = (dir / "model" / "frame_0000.rays").string();
    EXPECT_EQ(runCli("gpucheck-export --scene 'builtin:terrain?triangles=3000' --rays " + rays + " --out " +
                     (dir / "y").string())
                  .exitCode,
              2);
    EXPECT_EQ(runCli("gpucheck-export --scene " + scene + " --rays " + rays + " --ray-types sparkle --out " +
                     (dir / "y").string())
                  .exitCode,
              2);
    EXPECT_EQ(runCli("gpucheck-export --scene " + scene + " --rays " + rays + " --backend embree --out " +
                     (dir / "y").string())
                  .exitCode,
              2);
    EXPECT_EQ(runCli("gpucheck-export --scene " + scene + " --rays " + rays + " --ray-types shadow --out " +
                     (dir / "y").string())
                  .exitCode,
              2);  // no shadow rays in an AO render
    // Parameters the export's one launch of one ray per thread never uses: named, not ignored.
    for (const std::string inert :
         {"gpu.launch=tile", "shader.nextTraceLatency=999", "shader.anyHitLatency=5", "shader.intersectionLatency=5"}) {
        const CliRun r = runCli("gpucheck-export --scene " + scene + " --rays " + rays + " --rtcore-set " + inert +
                                " --out " + (dir / "y").string());
        EXPECT_EQ(r.exitCode, 2) << r.out;
        EXPECT_NE(r.out.find(inert.substr(0, inert.find('=')) + ": has no effect here: gpucheck-export"),
                  std::string::npos)
            << r.out;
    }
    EXPECT_FALSE(fs::exists(dir / "y" / "scene.bin"));
    EXPECT_EQ(runCli("gpucheck-export --scene " + scene + " --rays " + rays + " --rtcore-set gpu.launch=launch --out " +
                     (dir / "z").string())
                  .exitCode,
              0);  // what the export does anyway
}
