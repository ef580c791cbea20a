#pragma once
// Ray scheduling policies of the timing model (docs/rtcore-model.md,
// "Scheduler"). Each cycle the scheduler picks up to scheduler.issueWidth
// ready rays and issues their next traversal step; a policy decides which.
//
// Adding a built-in policy is one new file in rtcore_sim/src/policies/: it defines
//
//   const SchedulerPolicyEntry& rtcoreSimPolicy_<file stem>();
//
// returning its configuration name, a one-line description and a factory.
// rtcore_sim/CMakeLists.txt lists the files of that folder (sorted) into the
// registry at configure time, so the name is accepted by scheduler.policy
// once cmake has been re-run. A program that links the installed library
// registers its own policies at run time instead (registerSchedulerPolicy;
// examples/custom_scheduler).
#include <rtlab/rtcore_sim/config.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace rtlab::rtcore_sim {

// A ray that is ready to issue its next step.
struct ReadyRay {
    std::uint32_t slot = 0;  // ray slot index
    std::uint64_t age = 0;   // submission order across the core's life (smaller = older)
    std::uint64_t address =
        0;  // byte address of the node, leaf or instance its next step fetches (0 unless usesAddress())
};

// Bytes a policy asks the core to read into its node cache ahead of demand
// (treelet prefetching): lines not in the cache are allocated and filled
// through the core's memory port; no ray waits for them.
struct PrefetchRequest {
    std::uint64_t address = 0;
    std::uint32_t bytes = 0;
};

// Holds the ready rays; pop() chooses the next one to issue. Must be
// deterministic: the same push/pop sequence gives the same choices.
class SchedulerPolicy {
public:
    virtual ~SchedulerPolicy() = default;
    virtual void push(const ReadyRay& ray) = 0;
    // The ray to issue next; false when none is ready.
    virtual bool pop(ReadyRay& out) = 0;
    virtual std::size_t size() const = 0;
    // Whether push() needs ReadyRay::address (computing it costs a lookup per step).
    virtual bool usesAddress() const { return true; }
    // The next prefetch the policy asks for; false when none. The core drains
    // these after every issue phase, at that cycle.
    virtual bool takePrefetch(PrefetchRequest& out) {
        (void)out;
        return false;
    }
    // Policy-specific counters for the stats tree (may be empty).
    virtual void addStats(nlohmann::json& out) const { (void)out; }
    virtual void resetStats() {}
};

struct SchedulerPolicyEntry {
    std::string name;
    std::string description;
    std::unique_ptr<SchedulerPolicy> (*create)(const SchedulerParams& params) = nullptr;
};

// Every registered policy: the built-in ones sorted by file name, then the
// ones added by registerSchedulerPolicy in registration order.
std::vector<const SchedulerPolicyEntry*> schedulerPolicies();
std::vector<std::string> schedulerPolicyNames();
// Adds a policy from outside the library (a user's program, a test): its
// name becomes valid for scheduler.policy (RtCoreConfig JSON, set(),
// --rtcore-set) and for makeSchedulerPolicy. `entry` is not copied and must
// outlive every model that uses it (a function-local static is the usual
// home). Throws std::invalid_argument when the name is empty or taken or
// `create` is null. Thread-safe; register before building models that use it.
void registerSchedulerPolicy(const SchedulerPolicyEntry& entry);
// Throws InputError naming the known policies when `name` is not registered.
std::unique_ptr<SchedulerPolicy> makeSchedulerPolicy(const SchedulerParams& params);

}  // namespace rtlab::rtcore_sim
