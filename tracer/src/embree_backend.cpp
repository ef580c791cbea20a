#include <rtlab/tracer/embree_backend.hpp>

#include <algorithm>
#include <array>

namespace rtlab::tracer {

void EmbreeBackend::trace(const TraceEngine& engine, const TraceArgs& args, const RayDesc* rays,
                          void* const* payloads, const bool* active, std::size_t count, std::uint32_t depth,
                          CommittedHit* out, TraceCounters& counters) {
    if (count == 1) {
        if (active[0]) out[0] = engine.trace(args, rays[0], payloads[0], depth, counters);
        return;
    }
    for (std::size_t base = 0; base < count; base += 8) {
        const std::size_t lanes = std::min<std::size_t>(8, count - base);
        if (lanes == 8) {
            engine.trace8(args, rays + base, payloads + base, active + base, depth, out + base, counters, coherence_);
            continue;
        }
        // Step: a partial group padded with inactive lanes.
        std::array<RayDesc, 8> r{};
        std::array<void*, 8> p{};
        std::array<bool, 8> a{};
        std::array<CommittedHit, 8> h{};
        for (std::size_t i = 0; i < lanes; ++i) {
            r[i] = rays[base + i];
            p[i] = payloads[base + i];
            a[i] = active[base + i];
        }
        engine.trace8(args, r.data(), p.data(), a.data(), depth, h.data(), counters, coherence_);
        for (std::size_t i = 0; i < lanes; ++i)
            if (a[i]) out[base + i] = h[i];
    }
}

}  // namespace rtlab::tracer
