#include "participating_media.hpp"

#include <rtlab/ecs/volume_grid.hpp>

#include <algorithm>
#include <cmath>

namespace rtlab::shaders::detail {
namespace {
constexpr int kMaxSteps = 64;
}

std::vector<Medium> mediaOf(const ecs::SceneSnapshot& scene) {
    std::vector<Medium> media;
    for (const ecs::VolumeSnapshot& v : scene.volumes) {
        if (!v.grid || !(v.volume.densityScale > 0.f)) continue;
        Medium m;
        m.grid = v.grid.get();
        m.densityScale = v.volume.densityScale;
        m.albedo = glm::clamp(v.volume.albedo, vec3(0.f), vec3(1.f));
        m.bounds = v.grid->worldBounds();
        m.majorant = v.volume.densityScale * v.grid->maxDensity();
        if (!m.bounds.empty() && m.majorant > 0.f && std::isfinite(m.majorant)) media.push_back(m);
    }
    return media;
}

float extinction(const Medium& m, const vec3& p) { return m.densityScale * m.grid->density(p); }

bool clipToBox(const Aabb& box, const vec3& o, const vec3& d, float tMin, float tMax, float& t0, float& t1) {
    t0 = tMin;
    t1 = tMax;
    for (int a = 0; a < 3; ++a) {
        if (d[a] == 0.f) {
            if (o[a] < box.lo[a] || o[a] > box.hi[a]) return false;
            continue;
        }
        const float inv = 1.f / d[a];
        float tn = (box.lo[a] - o[a]) * inv, tf = (box.hi[a] - o[a]) * inv;
        if (tn > tf) std::swap(tn, tf);
        t0 = std::max(t0, tn);
        t1 = std::min(t1, tf);
    }
    return t0 < t1 && std::isfinite(t0);
}

float transmittance(const std::vector<Medium>& media, const vec3& o, const vec3& d, float tMax, const SampleKey& key,
                    std::uint32_t dim) {
    float T = 1.f;
    for (const Medium& m : media) {
        float t0, t1;
        if (!clipToBox(m.bounds, o, d, 0.f, tMax, t0, t1)) continue;
        const float length = (t1 - t0) * glm::length(d);
        if (!(length > 0.f)) continue;
        const float speed = glm::length(d);  // world distance per unit t
        if (m.majorant * length <= float(kMaxSteps)) {
            // Step: ratio tracking — tentative collisions at the majorant rate.
            float t = t0;
            for (int step = 0; step < 4 * kMaxSteps && T > 1e-6f; ++step) {
                const float u = sampleUniform(key, dim + static_cast<std::uint32_t>(step));
                t += -std::log(1.f - u) / (m.majorant * speed);
                if (t >= t1) break;
                const float sigma = m.densityScale * m.grid->density(o + t * d);
                T *= std::max(0.f, 1.f - sigma / m.majorant);
            }
        } else {
            // Step: optical depth by jittered midpoints (dense media, bounded work).
            const float dt = (t1 - t0) / float(kMaxSteps);
            const float jitter = sampleUniform(key, dim);
            double tau = 0.0;
            for (int step = 0; step < kMaxSteps; ++step)
                tau += double(m.densityScale * m.grid->density(o + (t0 + (step + jitter) * dt) * d)) * dt * speed;
            T *= static_cast<float>(std::exp(-tau));
        }
        if (!(T > 1e-6f)) return 0.f;
    }
    return std::clamp(T, 0.f, 1.f);
}

}  // namespace rtlab::shaders::detail
