// Fuzz target: a recorded ray trace (.rays, docs/ray-trace-format.md), read
// as `rtlab replay --scene builtin:cornell --rays case.rays` reads it, then,
// when it matches the scene, replayed on Embree and on the RT-core model.
// Each input is tried twice: as it is, and with its header's body checksum
// set to the body's, so that mutations of the body reach the batch parser
// (the checksum would reject nearly all of them).
#include "fuzz_input.hpp"

#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/session/frame_session.hpp>
#include <rtlab/study/ray_trace_file.hpp>
#include <rtlab/study/replay.hpp>

#include <cstddef>
#include <cstring>
#include <memory>
#include <vector>

namespace {

struct ReplayScene {
    std::unique_ptr<rtlab::session::FrameSession> session;
    std::uint64_t fingerprint = 0;
};
ReplayScene embree, rtcore;

ReplayScene makeScene(const char* backend) {
    rtlab::session::FrameOptions options;
    options.scene = "builtin:cornell";
    options.backend = backend;
    options.threads = 1;
    ReplayScene r;
    r.session = std::make_unique<rtlab::session::FrameSession>(options);
    r.session->load();
    r.fingerprint = rtlab::study::sceneFingerprint(r.session->advance().scene);
    return r;
}

void readAndReplay(const std::uint8_t* data, std::size_t size) {
    const std::filesystem::path path = rtlab::fuzz::writeInput(data, size, "case.rays");
    rtlab::fuzz::expectingInputErrors([&] {
        const rtlab::study::RayTraceFile file = rtlab::study::RayTraceFile::read(path);
        (void)file.info();
        for (ReplayScene* scene : {&embree, &rtcore}) {
            rtlab::fuzz::expectingInputErrors([&] {
                rtlab::rtcore_sim::RtCoreBackend* model = scene->session->rtcore();
                rtlab::study::checkReplayable(file, scene->fingerprint, model);
                if (model) model->beginFrame();
                rtlab::study::replayRays(file, scene->session->accel(), model);
            });
        }
    });
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
    rtlab::fuzz::initialize(argc, argv);
    embree = makeScene("embree");
    rtcore = makeScene("rtcore");
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    readAndReplay(data, size);
    constexpr std::size_t header = sizeof(rtlab::study::RayTraceHeader);
    if (size >= header) {
        std::vector<std::uint8_t> fixed(data, data + size);
        rtlab::study::Fnv64 sum;
        sum.add(fixed.data() + header, size - header);
        const std::uint64_t checksum = sum.value();
        std::memcpy(fixed.data() + offsetof(rtlab::study::RayTraceHeader, bodyChecksum), &checksum, sizeof checksum);
        if (std::memcmp(fixed.data(), data, header) != 0) readAndReplay(fixed.data(), fixed.size());
    }
    return 0;
}
