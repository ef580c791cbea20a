// The pipeline's shared state: per-ray-type counters and the per-thread
// trace scope (recursion depth, the counters of the tile being worked on).
#include <rtlab/tracer/pipeline.hpp>

namespace rtlab::tracer {

void TraceCounters::add(const TraceCounters& o) {
    for (std::size_t i = 0; i < kRayTypes; ++i) {
        rays[i] += o.rays[i];
        hits[i] += o.hits[i];
        misses[i] += o.misses[i];
    }
    anyHitInvocations += o.anyHitInvocations;
    intersectionInvocations += o.intersectionInvocations;
    closestHitInvocations += o.closestHitInvocations;
    missInvocations += o.missInvocations;
    packetsTraced += o.packetsTraced;
}

std::uint64_t TraceCounters::totalRays() const {
    std::uint64_t n = 0;
    for (std::uint64_t r : rays) n += r;
    return n;
}

TraceScope& currentTraceScope() {
    thread_local TraceScope scope;
    return scope;
}

}  // namespace rtlab::tracer
