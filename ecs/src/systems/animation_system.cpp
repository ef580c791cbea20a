// Animation sampling: evaluates every clip's channels at the world time
// (clips loop over their duration) and patches the targets whose value
// actually changes, so a static pose dirties nothing.
#include "../world_dirty_sets.hpp"

#include <algorithm>
#include <cmath>

namespace rtlab::ecs {
namespace {

// Key interval containing t: index of the left key and the blend factor.
struct KeySpan {
    std::size_t left = 0;
    std::size_t right = 0;
    float u = 0.f;
    float dt = 0.f;
};

KeySpan findSpan(const std::vector<float>& times, float t) {
    KeySpan s;
    if (times.size() < 2 || t <= times.front()) return s;
    if (t >= times.back()) {
        s.left = s.right = times.size() - 1;
        return s;
    }
    const auto it = std::upper_bound(times.begin(), times.end(), t);
    s.right = static_cast<std::size_t>(it - times.begin());
    s.left = s.right - 1;
    s.dt = times[s.right] - times[s.left];
    s.u = s.dt > 0.f ? (t - times[s.left]) / s.dt : 0.f;
    return s;
}

// Samples `n` components of a channel at time t into out.
void sampleChannel(const AnimationChannel& c, float t, std::vector<float>& out) {
    const std::size_t n = c.componentsPerKey;
    out.assign(n, 0.f);
    if (c.times.empty()) return;
    const KeySpan s = findSpan(c.times, t);
    if (c.interpolation == Interpolation::CubicSpline) {
        // Layout per key: in-tangent[n], value[n], out-tangent[n] (glTF 2.0 spec, Appendix C).
        auto at = [&](std::size_t key, std::size_t part, std::size_t i) { return c.values[(key * 3 + part) * n + i]; };
        if (s.left == s.right || s.u == 0.f) {
            for (std::size_t i = 0; i < n; ++i) out[i] = at(s.left, 1, i);
        } else {
            const float u = s.u, u2 = u * u, u3 = u2 * u;
            const float h00 = 2 * u3 - 3 * u2 + 1, h10 = u3 - 2 * u2 + u, h01 = -2 * u3 + 3 * u2, h11 = u3 - u2;
            for (std::size_t i = 0; i < n; ++i)
                out[i] = h00 * at(s.left, 1, i) + h10 * s.dt * at(s.left, 2, i) + h01 * at(s.right, 1, i) +
                         h11 * s.dt * at(s.right, 0, i);
        }
    } else if (c.interpolation == Interpolation::Step || s.left == s.right) {
        for (std::size_t i = 0; i < n; ++i) out[i] = c.values[s.left * n + i];
    } else if (c.path == AnimationPath::Rotation) {
        const float* a = &c.values[s.left * 4];
        const float* b = &c.values[s.right * 4];
        const quat q = glm::slerp(quat(a[3], a[0], a[1], a[2]), quat(b[3], b[0], b[1], b[2]), s.u);
        out = {q.x, q.y, q.z, q.w};
    } else {
        for (std::size_t i = 0; i < n; ++i)
            out[i] = (1.f - s.u) * c.values[s.left * n + i] + s.u * c.values[s.right * n + i];
    }
}

}  // namespace

void World::runAnimationSystem() {
    std::vector<float> v;
    for (const AnimationClip& clip : animations_) {
        const float duration = clip.duration();
        const float t = duration > 0.f ? std::fmod(time_, duration) : 0.f;
        for (const AnimationChannel& c : clip.channels) {
            if (!alive(c.target)) continue;
            sampleChannel(c, t, v);
            if (c.path == AnimationPath::Weights) {
                const MorphWeights* current = get<MorphWeights>(c.target);
                if (current && current->weights == v) continue;
                if (!current) emplace(c.target, MorphWeights{v});
                else patch<MorphWeights>(c.target, [&](MorphWeights& w) { w.weights = v; });
                continue;
            }
            if (!has<LocalTransform>(c.target)) emplace(c.target, LocalTransform{});
            LocalTransform next = *get<LocalTransform>(c.target);
            switch (c.path) {
                case AnimationPath::Translation: next.translation = vec3(v[0], v[1], v[2]); break;
                case AnimationPath::Scale: next.scale = vec3(v[0], v[1], v[2]); break;
                case AnimationPath::Rotation: next.rotation = glm::normalize(quat(v[3], v[0], v[1], v[2])); break;
                case AnimationPath::Weights: break;
            }
            const LocalTransform& cur = *get<LocalTransform>(c.target);
            if (next.translation == cur.translation && next.rotation == cur.rotation && next.scale == cur.scale)
                continue;
            patch<LocalTransform>(c.target, [&](LocalTransform& l) { l = next; });
        }
    }
}

}  // namespace rtlab::ecs
