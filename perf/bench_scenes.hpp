#pragma once
// Scene set-up shared by the benchmarks.
#include <rtlab/session/frame_session.hpp>
#include <rtlab/shaders_cpp/preview_shading.hpp>

#include <memory>
#include <string>

namespace rtlab::bench {

// A loaded scene after its first update (frame 0 of the frame driver), with
// built acceleration structures; `options` vary Embree's (e.g. native triangles).
struct LoadedScene {
    std::unique_ptr<session::FrameSession> session;
    const ecs::SceneSnapshot& snapshot;
    const tracer::AccelManager* accel;

    explicit LoadedScene(const std::string& source, tracer::AccelOptions options = {})
        : session(start(source, options)), snapshot(session->frame().scene), accel(&session->accel()) {}
    // The scene's camera for one image size (build it outside per-pixel loops).
    shaders::PinholeCamera camera(int width, int height) const { return {snapshot.camera, width, height}; }

private:
    static std::unique_ptr<session::FrameSession> start(const std::string& source, tracer::AccelOptions options) {
        session::FrameOptions o;
        o.scene = source;
        auto s = std::make_unique<session::FrameSession>(o, session::Stages::Render, options);
        s->load();
        s->advance();
        return s;
    }
};

// The primary ray through the centre of pixel (x, y).
inline tracer::RayDesc primaryRay(const shaders::PinholeCamera& camera, int x, int y) {
    const shaders::CameraRay r = camera.ray(x + 0.5f, y + 0.5f);
    return {r.origin, 0.f, r.direction, kInfinity};
}

}  // namespace rtlab::bench
