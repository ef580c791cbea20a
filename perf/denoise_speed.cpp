// longer than 800 lines: one benchmark program (perf/ builds one executable per .cpp) whose synthetic
// frame sequence (Scene below) serves only its own benchmarks; clang-format took it past 800 (778 before).
// Denoiser cost at 1920x1080: every stage alone, every per-effect stack per
// frame in steady state, and the a-trous iteration against the memory-bound
// limit. The first argument of every benchmark is the thread count (1, 2;
// rtlab::ThreadLimit). Inputs are a deterministic synthetic frame sequence
// (see Scene below): a perspective ground plane under a skyline and a sky
// strip, boxes and spheres standing on it (depth and normal edges, 15 mesh
// ids), 1-spp-like noise from the PCG hash with rare fireflies, and a camera
// moving sideways, so motion is mostly sub-pixel, varies with depth, and
// uncovers ground behind every object each frame.
//
// Stages, on frame 6 with the history of frames 0..5 (guides carry their depth
// gradient, as inside SvgfFilter and EffectLayerDenoiser):
//   BM_DenoiseDepthGradient      depthGradient()
//   BM_DenoiseReproject          reproject() of frame 6 against frame 5
//   BM_DenoiseReprojectHistory   reprojectHistory() through that reprojection
//   BM_DenoiseTemporal           accumulateTemporal()
//   BM_DenoiseVariance/T/H       estimateVariance(); H 1 = warm history (temporal
//                                estimate, the 7x7 spatial one only where disoccluded),
//                                H 0 = every history length 1 (7x7 everywhere: the first frames)
//   BM_DenoiseAtrousIteration/T/S  atrousIteration() with step S (1, 16): the public
//                                call, which converts the inputs to planes on every call
//   BM_DenoiseAtrousFilter/T/I   atrousFilter() with I iterations (1, 5), a kept
//                                AtrousWorkspace and the feedback tap after 1, as SvgfFilter
//                                calls it; perf/summarize.py takes (t5 - t1) / 4 as the
//                                cost of one iteration inside the filter
//   BM_DenoiseAtrousRmw/T/L      the memory-bound reference for one iteration (below)
//   BM_DenoiseFireflyClamp       clampFireflies(), 3x3, k 3
//   BM_DenoiseHistoryClamp       clampHistory(), mean +- 1 sigma over 5x5 (the shadow and
//                                reflection stacks' setting), in place
//   BM_DenoiseModulation         demodulate() + remodulate()
//   BM_DenoiseFootprint/T/K      shadowFootprint (K 0), reflectionFootprint (1), aoFootprint (2)
// Stacks, per frame in steady state: after 3 warm-up frames every pixel that
// kept its history has length >= 4 (temporal variance); each timed frame is
// synthesised with the timer paused; the 2-thread run continues the 1-thread
// run's frame sequence (see StackRun):
//   BM_DenoiseStack/T/K          SvgfFilter::filter with StackParams::of(K) (0 svgf
//                                paper on GI, 1 shadow on one light's visibility, 2 reflection,
//                                3 ao), its footprint computed in the timed frame as
//                                EffectLayerDenoiser does (the frame's depth gradient is
//                                part of the G-buffer here: computed with the timer paused)
//   BM_DenoiseEffectLayers/T     EffectLayerDenoiser({shadows, ao, gi})::apply on an Image
//                                with the G-buffer layers, shadow.light0.V/penumbra,
//                                ao.V/hitT and gi.RGB (three layers, guides built from the
//                                channels, depth gradient included)
// Times include what a call allocates for its outputs and scratch, under the
// rtlab binary's malloc policy (apps/src/main.cpp: freed memory stays in the
// heap, so a steady-state call reuses pages instead of page-faulting fresh
// ones; see main() below).
// Counters: megapixels_per_s (1920x1080 per iteration); the RMW reference also
// reports bytes_per_second. perf/summarize.py turns the times into the
// "denoise" section of out/bench/summary.json.
#include <rtlab/core/image.hpp>
#include <rtlab/core/memory.hpp>
#include <rtlab/core/parallel.hpp>
#include <rtlab/core/rng.hpp>
#include <rtlab/denoise/atrous.hpp>
#include <rtlab/denoise/clamp.hpp>
#include <rtlab/denoise/effect_layers.hpp>
#include <rtlab/denoise/footprint.hpp>
#include <rtlab/denoise/modulation.hpp>
#include <rtlab/denoise/reprojection.hpp>
#include <rtlab/denoise/svgf.hpp>
#include <rtlab/denoise/temporal.hpp>
#include <rtlab/denoise/variance.hpp>

#include <benchmark/benchmark.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace {

using namespace rtlab;
using namespace rtlab::denoise;

constexpr int kWidth = 1920, kHeight = 1080;
constexpr std::size_t kPixels = static_cast<std::size_t>(kWidth) * kHeight;
constexpr float kFocal = 1000.f;       // pixels; a pixel at depth z is z / kFocal wide
constexpr float kCameraHeight = 1.6f;  // the ground plane's depth is kFocal * kCameraHeight / (y - kHorizon)
constexpr float kHorizon = 300.f;
constexpr float kSkylineDepth = 130.f;
constexpr float kAoRadius = 1.f;
// The camera moves sideways by kCameraStep world units per frame, so a surface
// at depth z moves kCameraStep * kFocal / z pixels per frame on screen: 3 px at
// the bottom of the ground plane (z 2), 1.7 px on the nearest sphere, 0.05 px on
// the skyline, 0 on the sky. The parallax uncovers ground behind every box and
// sphere each frame, the screen border brings new pixels, and most motion is
// sub-pixel, so reprojection takes bilinear taps and rejects some.
constexpr float kCameraStep = 0.02f;
constexpr int kWarmFrames = 3;  // stacks: frames filtered before timing (then history length >= 4)

// ---------------------------------------------------------------------------
// The synthetic scene. Objects are given by where they are on screen in frame
// 0; in frame f an object at depth z has moved f * m pixels to the left,
// m = kCameraStep * kFocal / z, and its motion vector (previous position minus
// current) is (+m, 0).
struct Box {
    float x0, x1, top, base, depth;  // front face [x0, x1] x [top, base] in frame 0; right 22% is a side face
    int id;
};
struct Ball {
    float cx, cy, r, depth;
    int id;
};

float screenMotion(float depth) { return kCameraStep * kFocal / depth; }
float groundDepth(float sy) { return kFocal * kCameraHeight / (sy - kHorizon); }

struct Scene {
    std::vector<Box> boxes;
    std::array<Ball, 3> balls{
        {{400.f, 700.f, 90.f, 6.f, 20}, {1250.f, 560.f, 70.f, 9.f, 21}, {1650.f, 880.f, 120.f, 3.5f, 22}}};

    Scene() {
        for (int b = 0; b < 10; ++b) {
            const std::uint32_t h = pcgHash(static_cast<std::uint32_t>(b) * 7919u + 17u);
            const float base = 480.f + 130.f * static_cast<float>(b % 5) + static_cast<float>(h % 40u);
            const float cx = 120.f + 190.f * static_cast<float>(b) + static_cast<float>((h >> 8) % 80u) - 40.f;
            const float w = 90.f + static_cast<float>((h >> 16) % 130u);
            boxes.push_back({cx - w / 2, cx + w / 2, base - 1.3f * w, base, groundDepth(base), 1 + b});
        }
    }
};

const Scene& scene() {
    static const Scene s;
    return s;
}

// Everything the passes would have written for one pixel.
struct Sample {
    int meshId = -1;
    float depth = 0.f, pixelWorld = 0.f;
    vec3 normal{0.f, 0.f, 1.f};
    vec2 motion{0.f};
    vec3 gi{0.f}, reflection{0.f}, albedo{1.f};
    float shadowV = 1.f, penumbraWorld = 0.f, aoV = 1.f, aoHitT = kAoRadius, roughness = 1.f, reflectionHitT = 0.f;
};

float unit(std::uint32_t h) { return static_cast<float>(h >> 8) * (1.f / 16777216.f); }

// Pixel centre (sx, sy) of frame `frame`.
Sample shade(float sx, float sy, std::uint32_t pixel, std::uint32_t frame) {
    const Scene& sc = scene();
    const float fr = static_cast<float>(frame);
    // Per-pixel, per-frame random numbers: one hash chain.
    const std::uint32_t h0 = pcgHash(pcgHash(pixel ^ 0x9e3779b9u) ^ (frame * 0x85ebca6bu + 12345u));
    const float u0 = unit(pcgHash(h0 + 1u)), u1 = unit(pcgHash(h0 + 2u)), u2 = unit(pcgHash(h0 + 3u));
    const bool firefly = (h0 & 0x7ffu) == 0u;                             // 1 in 2048
    const float expNoise = -std::log(1.f - u0) * (firefly ? 40.f : 1.f);  // mean 1: a 1-spp estimate

    Sample s;
    float light = 0.f, shadowAmount = 0.f, penumbraPx = 0.f, contactPx = 1e9f;
    vec3 tint(0.8f);
    // The nearest sphere or box, else the ground, the skyline or the sky.
    float nearest = kInfinity;
    for (const Ball& b : sc.balls) {
        const float m = screenMotion(b.depth);
        const float dx = (sx + fr * m - b.cx) / b.r, dy = (sy - b.cy) / b.r, rho2 = dx * dx + dy * dy;
        if (rho2 >= 1.f || b.depth >= nearest) continue;
        nearest = b.depth;
        const float nz = std::sqrt(1.f - rho2);
        s.meshId = b.id;
        s.normal = vec3(dx, -dy, nz);
        s.depth = b.depth - nz * b.r * b.depth / kFocal;
        s.motion = vec2(m, 0.f);
        light = 0.05f + 0.9f * std::max(0.f, glm::dot(s.normal, vec3(-0.48f, 0.6f, 0.64f)));
        tint = vec3(0.9f, 0.3f + 0.2f * static_cast<float>(b.id - 20), 0.2f);
        s.roughness = b.id == 20 ? 0.f : 0.2f;
        s.reflectionHitT = 4.f + u1;
    }
    for (const Box& b : sc.boxes) {
        const float m = screenMotion(b.depth), x = sx + fr * m;
        if (x < b.x0 || x >= b.x1 || sy < b.top || sy >= b.base || b.depth >= nearest) continue;
        nearest = b.depth;
        s.meshId = b.id;
        s.motion = vec2(m, 0.f);
        const float side = b.x1 - 0.22f * (b.x1 - b.x0);
        if (x < side) {
            s.normal = vec3(0.f, 0.f, 1.f);
            s.depth = b.depth;
        } else {
            s.normal = vec3(0.70710678f, 0.f, 0.70710678f);
            s.depth = b.depth * (1.f + 0.3f * (x - side) / (b.x1 - b.x0));
        }
        light = 0.35f + 0.04f * static_cast<float>(b.id % 5);
        tint = vec3(0.3f + 0.06f * static_cast<float>(b.id), 0.6f, 0.8f - 0.05f * static_cast<float>(b.id));
        s.roughness = b.id % 2 == 0 ? 0.05f : 0.5f;
        s.reflectionHitT = 5.f + u1;
    }
    if (s.meshId < 0) {
        const float ms = screenMotion(kSkylineDepth);
        const float block = std::floor((sx + fr * ms) / 110.f);
        const std::uint32_t bh = pcgHash(static_cast<std::uint32_t>(static_cast<std::int32_t>(block)) + 99u);
        const float skyline = kHorizon - 40.f - static_cast<float>(bh % 90u);
        if (sy < skyline) {  // sky: a constant colour, no noise, no motion
            s.gi = s.reflection = vec3(0.45f, 0.65f, 1.1f);
            return s;
        }
        if (sy < kHorizon + 6.f) {  // the skyline's facades
            s.meshId = 30;
            s.depth = kSkylineDepth - 20.f + static_cast<float>(bh % 40u);
            s.normal = vec3(0.f, 0.f, 1.f);
            s.motion = vec2(ms, 0.f);
            light = 0.2f;
            tint = vec3(0.6f, 0.55f, 0.5f);
            s.roughness = 0.8f;
        } else {  // the ground plane, with a gentle normal ripple
            s.meshId = 0;
            s.depth = groundDepth(sy);
            const float m = screenMotion(s.depth);
            s.motion = vec2(m, 0.f);
            const float gx = sx + fr * m;  // where this ground point was in frame 0
            s.normal = glm::normalize(vec3(0.05f * std::sin(gx * 0.045f), 1.f, 0.05f * std::cos(sy * 0.032f)));
            light = 0.5f + 0.25f * std::sin(gx * 0.006f) * std::cos(sy * 0.011f);
            tint = vec3(0.9f, 0.8f, 0.7f);
            s.roughness = 0.3f + 0.15f * std::sin(gx * 0.01f);
            // Box shadows on the ground (fixed in the world: the box's x range scaled to this row's
            // depth, sheared away from the light), penumbra widening with the distance to the contact;
            // AO darkens near the boxes' bases; the glossy ground reflects the boxes behind it.
            for (const Box& b : sc.boxes) {
                const float along = sy - b.base;
                const float scale = b.depth / s.depth;
                const float x0 = b.x0 * scale, x1 = b.x1 * scale;
                if (along >= -2.f && gx >= x0 - 4.f && gx < x1 + 4.f)
                    contactPx = std::min(contactPx, std::max(0.f, along));
                if (along < 0.f) continue;
                const float length = 0.6f * (x1 - x0), shear = 0.3f * along;
                const float pen = 2.f + 0.35f * along;
                const float d = std::max({x0 + shear - gx, gx - (x1 + shear), along - length});
                const float amount = std::clamp(0.5f - d / pen, 0.f, 1.f);
                if (amount > shadowAmount) shadowAmount = amount, penumbraPx = pen;
                if (gx >= x0 && gx < x1 && s.reflectionHitT == 0.f)
                    s.reflectionHitT = 2.f * along * s.depth / kFocal + 0.1f;
            }
        }
    }
    s.pixelWorld = s.depth / kFocal;
    s.albedo = tint;
    // Shadow: one light sample, visible with probability 1 - shadowAmount; where it is blocked the
    // pass reports the PCSS penumbra width, elsewhere 0.
    s.shadowV = u1 >= shadowAmount ? 1.f : 0.f;
    s.penumbraWorld = s.shadowV == 0.f ? penumbraPx * s.pixelWorld : 0.f;
    // AO: occluded with probability 0.08 + 0.5 exp(-contact / 25 px); the occluder distance grows
    // with the distance to the contact.
    const float aoOccluded = 0.08f + 0.5f * std::exp(-contactPx / 25.f);
    s.aoV = u2 >= aoOccluded ? 1.f : 0.f;
    s.aoHitT = s.aoV == 1.f ? kAoRadius : std::min(kAoRadius, (0.02f + contactPx * s.pixelWorld) * (0.5f + u1));
    // GI irradiance (albedo demodulated) and reflected radiance: noisy 1-spp estimates.
    s.gi = vec3(light * (1.f - 0.7f * shadowAmount) * expNoise) * tint;
    const float r = s.roughness;
    s.reflection = vec3(0.45f, 0.6f, 0.9f) * (1.f - r + r * expNoise) * (s.reflectionHitT > 0.f ? 0.4f : 1.f);
    return s;
}

struct Frame {
    GuideBuffers guides{kWidth, kHeight};
    std::vector<vec3> gi, reflection, albedo;
    std::vector<float> shadowV, penumbraWorld, aoV, aoHitT, roughness, reflectionHitT, pixelWorld;
    Frame()
        : gi(kPixels), reflection(kPixels), albedo(kPixels), shadowV(kPixels), penumbraWorld(kPixels), aoV(kPixels),
          aoHitT(kPixels), roughness(kPixels), reflectionHitT(kPixels), pixelWorld(kPixels) {}
};

// Synthesises frame `f` into `out` (rows in parallel); the depth gradient is
// computed too unless `withGradient` is false.
void synthesise(std::uint32_t f, Frame& out, bool withGradient = true) {
    parallelForEach(kHeight, [&](std::size_t y) {
        for (int x = 0; x < kWidth; ++x) {
            const std::size_t i = y * kWidth + static_cast<std::size_t>(x);
            const Sample s =
                shade(static_cast<float>(x) + 0.5f, static_cast<float>(y) + 0.5f, static_cast<std::uint32_t>(i), f);
            out.guides.depth[i] = s.depth;
            out.guides.normal[i] = s.normal;
            out.guides.meshId[i] = s.meshId;
            out.guides.motion[i] = s.motion;
            out.gi[i] = s.gi;
            out.reflection[i] = s.reflection;
            out.albedo[i] = s.albedo;
            out.shadowV[i] = s.shadowV;
            out.penumbraWorld[i] = s.penumbraWorld;
            out.aoV[i] = s.aoV;
            out.aoHitT[i] = s.aoHitT;
            out.roughness[i] = s.roughness;
            out.reflectionHitT[i] = s.reflectionHitT;
            out.pixelWorld[i] = s.pixelWorld;
        }
    });
    out.guides.depthGrad.clear();
    if (withGradient) ensureDepthGradient(out.guides);
}

std::vector<vec3> grey(const std::vector<float>& v) {
    std::vector<vec3> out(v.size());
    for (std::size_t i = 0; i < v.size(); ++i) out[i] = vec3(v[i]);
    return out;
}

// ---------------------------------------------------------------------------
// The stage inputs: frames 5 (previous) and 6 (current), and the history the
// stages built over frames 0..5 (reproject, reprojectHistory, accumulateTemporal).
struct Workload {
    Frame previous, current;
    Reprojection reprojection;    // current against previous
    HistoryBuffers history;       // after frame 5
    HistoryBuffers reprojected;   // history gathered into frame 6
    HistoryBuffers accumulated;   // frame 6 accumulated
    HistoryBuffers shortHistory;  // accumulated with every length 1
    std::vector<float> variance;  // estimateVariance of accumulated

    Workload() {
        for (std::uint32_t f = 0; f <= 6; ++f) {
            std::swap(previous, current);
            synthesise(f, current);
            if (f == 0) {
                reprojected.resize(kWidth, kHeight);
            } else {
                reprojection = reproject(current.guides, previous.guides);
                reprojectHistory(reprojection, history, reprojected);
            }
            accumulateTemporal(current.gi, reprojected, TemporalParams{}, accumulated);
            if (f < 6) history = accumulated;
        }
        shortHistory = accumulated;
        std::fill(shortHistory.length.begin(), shortHistory.length.end(), 1.f);
        variance.resize(kPixels);
        estimateVariance(current.guides, accumulated, VarianceParams{}, variance);
    }
};

const Workload& workload() {
    static const Workload w;
    return w;
}

void setRate(benchmark::State& state) {
    state.counters["megapixels_per_s"] =
        benchmark::Counter(static_cast<double>(kPixels) * 1e-6, benchmark::Counter::kIsIterationInvariantRate);
}

int threadsOf(const benchmark::State& state) { return static_cast<int>(state.range(0)); }

// Times `call`, after one untimed call: the heap has grown to the call's
// working set (steady state, as from the second frame on in a renderer).
template <class Call>
void timeCalls(benchmark::State& state, Call&& call) {
    call();
    for (auto _ : state) call();
    setRate(state);
}

// ---------------------------------------------------------------------------
// Stages.

void BM_DenoiseDepthGradient(benchmark::State& state) {
    const Workload& w = workload();  // built on all threads, once
    const ThreadLimit limit(threadsOf(state));
    timeCalls(state, [&] {
        std::vector<vec2> g = depthGradient(w.current.guides);
        benchmark::DoNotOptimize(g.data());
    });
}

void BM_DenoiseReproject(benchmark::State& state) {
    const Workload& w = workload();  // built on all threads, once
    const ThreadLimit limit(threadsOf(state));
    timeCalls(state, [&] {
        const Reprojection r = reproject(w.current.guides, w.previous.guides);
        benchmark::DoNotOptimize(r.taps.data());
    });
    state.counters["valid_fraction"] = static_cast<double>(w.reprojection.validCount()) / static_cast<double>(kPixels);
}

void BM_DenoiseReprojectHistory(benchmark::State& state) {
    const Workload& w = workload();  // built on all threads, once
    const ThreadLimit limit(threadsOf(state));
    HistoryBuffers out;
    timeCalls(state, [&] {
        reprojectHistory(w.reprojection, w.history, out);
        benchmark::DoNotOptimize(out.color.data());
    });
}

void BM_DenoiseTemporal(benchmark::State& state) {
    const Workload& w = workload();  // built on all threads, once
    const ThreadLimit limit(threadsOf(state));
    HistoryBuffers out = w.accumulated;  // sized: accumulateTemporal only resizes
    timeCalls(state, [&] {
        accumulateTemporal(w.current.gi, w.reprojected, TemporalParams{}, out);
        benchmark::DoNotOptimize(out.color.data());
    });
}

void BM_DenoiseVariance(benchmark::State& state) {
    const Workload& w = workload();  // built on all threads, once
    const ThreadLimit limit(threadsOf(state));
    const HistoryBuffers& history = state.range(1) != 0 ? w.accumulated : w.shortHistory;
    state.SetLabel(state.range(1) != 0 ? "warm history" : "history 1 (spatial 7x7 everywhere)");
    std::vector<float> variance(kPixels);
    timeCalls(state, [&] {
        estimateVariance(w.current.guides, history, VarianceParams{}, variance);
        benchmark::DoNotOptimize(variance.data());
    });
}

void BM_DenoiseAtrousIteration(benchmark::State& state) {
    const Workload& w = workload();  // built on all threads, once
    const ThreadLimit limit(threadsOf(state));
    const int step = static_cast<int>(state.range(1));
    state.SetLabel("step " + std::to_string(step));
    std::vector<vec3> color(kPixels);
    std::vector<float> variance(kPixels);
    timeCalls(state, [&] {
        atrousIteration(w.current.guides, w.accumulated.color, w.variance, step, AtrousParams{}, color, variance);
        benchmark::DoNotOptimize(color.data());
    });
}

void BM_DenoiseAtrousFilter(benchmark::State& state) {
    const Workload& w = workload();  // built on all threads, once
    const ThreadLimit limit(threadsOf(state));
    AtrousParams params;
    params.iterations = static_cast<int>(state.range(1));
    state.SetLabel(std::to_string(params.iterations) + " iterations, kept workspace, tap 1");
    AtrousWorkspace workspace;
    std::vector<vec3> color(kPixels), tap(kPixels);
    std::vector<float> variance(kPixels);
    timeCalls(state, [&] {  // the untimed first call allocates the workspace
        atrousFilter(w.current.guides, w.accumulated.color, w.variance, params, color, variance, 1, tap, {},
                     &workspace);
        benchmark::DoNotOptimize(color.data());
    });
}

// The memory-bound reference of one a-trous iteration: a read-modify-write
// pass that reads every byte an iteration must read once and writes every
// byte it must write once, with trivial arithmetic, parallelised the same way
// (parallelForEach, one task per row).
//
// What one iteration must move (per pixel, float = 4 bytes):
//   reads   colour (3 floats), variance (1), depth (1), normal (3), geometry
//           (mesh id or sky flag, 1), depth gradient (2)      = 44 bytes
//   writes  colour (3), variance (1)                          = 16 bytes
// Argument L selects the layout of those bytes:
//   L 0  the buffers atrousIteration() receives: vec3 colour, float variance,
//        GuideBuffers depth / normal (vec3) / meshId (int) / depthGrad (vec2),
//        vec3 + float outputs: 12+4+4+12+4+8 read, 12+4 written.
//   L 1  the structure-of-arrays planes an iteration inside atrousFilter()
//        works on (denoise/src/atrous.cpp: r, g, b, variance, depth, nx, ny,
//        nz, gradX, gradY, geometry read; r, g, b, variance written): 11 x 4
//        read, 4 x 4 written.
// Both are 60 bytes per pixel, 124 MB per 1920x1080 pass. What the a-trous
// code actually moves is more, by construction:
//   - inside atrousFilter, one iteration (iterate()) reads the 11 planes and the
//     luminance plane (48 B; the 3x3 variance blur of the luminance scale reads
//     variance and geometry again, from cache) and writes r, g, b, variance and
//     the luminance for the next iteration (20 B): 68 B per pixel when the 5 tap
//     rows stay in cache (step 16 reaches rows y +- 32: about 5 MB of tap planes
//     between a row's first and last use), ~1.13x the reference;
//   - atrousIteration() additionally builds a fresh AtrousWorkspace every
//     call: converts the guides to 7 planes (reads 28 B, writes 28 B into
//     zero-filled new allocations, another 28 B + page faults), loads the
//     signal into r/g/b/variance planes (16 B in, 16 B out, 40 B zero-fill of
//     two plane sets) and stores it back (16 B in, 16 B out): ~300 B per
//     pixel, so ~5x the reference even if it ran at full bandwidth.
void BM_DenoiseAtrousRmw(benchmark::State& state) {
    const Workload& w = workload();  // built on all threads, once
    const ThreadLimit limit(threadsOf(state));
    const bool planes = state.range(1) != 0;
    state.SetLabel(planes ? "SoA planes (inside atrousFilter)" : "atrousIteration's buffers (vec3, GuideBuffers)");
    constexpr float kA = 0.999f, kB = 1e-30f;  // trivial arithmetic: out = a * in + b * (sum of the guides)
    if (!planes) {
        const GuideBuffers& g = w.current.guides;
        const vec3* color = w.accumulated.color.data();
        const float* variance = w.variance.data();
        std::vector<vec3> colorOut(kPixels);
        std::vector<float> varianceOut(kPixels);
        for (auto _ : state) {
            parallelForEach(kHeight, [&](std::size_t y) {
                const std::size_t row = y * kWidth;
                for (std::size_t i = row; i < row + kWidth; ++i) {
                    const vec3 n = g.normal[i];
                    const vec2 d = g.depthGrad[i];
                    const float guide = g.depth[i] + n.x + n.y + n.z + d.x + d.y + static_cast<float>(g.meshId[i]);
                    colorOut[i] = kA * color[i] + kB * guide;
                    varianceOut[i] = kA * variance[i] + kB * guide;
                }
            });
            benchmark::DoNotOptimize(colorOut.data());
            benchmark::DoNotOptimize(varianceOut.data());
        }
    } else {
        // 11 input planes and 4 output planes (the layout is what matters, not the values).
        std::vector<std::vector<float>> in(11, std::vector<float>(kPixels)), out(4, std::vector<float>(kPixels));
        parallelForEach(kHeight, [&](std::size_t y) {
            for (std::size_t i = y * kWidth; i < (y + 1) * kWidth; ++i) {
                const vec3 c = w.accumulated.color[i], n = w.current.guides.normal[i];
                const vec2 d = w.current.guides.depthGrad[i];
                const float values[11] = {c.r,
                                          c.g,
                                          c.b,
                                          w.variance[i],
                                          w.current.guides.depth[i],
                                          n.x,
                                          n.y,
                                          n.z,
                                          d.x,
                                          d.y,
                                          w.current.guides.meshId[i] < 0 ? 0.f : 1.f};
                for (int k = 0; k < 11; ++k) in[k][i] = values[k];
            }
        });
        const float* p[11];
        for (int k = 0; k < 11; ++k) p[k] = in[k].data();
        float* o[4] = {out[0].data(), out[1].data(), out[2].data(), out[3].data()};
        for (auto _ : state) {
            parallelForEach(kHeight, [&](std::size_t y) {
                const std::size_t row = y * kWidth;
                for (std::size_t i = row; i < row + kWidth; ++i) {
                    const float guide = p[4][i] + p[5][i] + p[6][i] + p[7][i] + p[8][i] + p[9][i] + p[10][i];
                    o[0][i] = kA * p[0][i] + kB * guide;
                    o[1][i] = kA * p[1][i] + kB * guide;
                    o[2][i] = kA * p[2][i] + kB * guide;
                    o[3][i] = kA * p[3][i] + kB * guide;
                }
            });
            benchmark::DoNotOptimize(o[0]);
        }
    }
    state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) * static_cast<std::int64_t>(kPixels) * 60);
    setRate(state);
}

void BM_DenoiseFireflyClamp(benchmark::State& state) {
    const Workload& w = workload();  // built on all threads, once
    const ThreadLimit limit(threadsOf(state));
    std::vector<vec3> out(kPixels);
    timeCalls(state, [&] {
        clampFireflies(kWidth, kHeight, w.current.gi, out);
        benchmark::DoNotOptimize(out.data());
    });
}

void BM_DenoiseHistoryClamp(benchmark::State& state) {
    const Workload& w = workload();  // built on all threads, once
    const ThreadLimit limit(threadsOf(state));
    const HistoryClampParams params = StackParams::shadow().svgf.historyClamp;
    // In place, as SvgfFilter does; after the first call the history is inside its bounds, which changes
    // no work (the window statistics are computed for every pixel with history either way).
    std::vector<vec3> history = w.reprojected.color;
    timeCalls(state, [&] {
        clampHistory(kWidth, kHeight, w.current.gi, history, w.reprojected.length, params);
        benchmark::DoNotOptimize(history.data());
    });
}

void BM_DenoiseModulation(benchmark::State& state) {
    const Workload& w = workload();  // built on all threads, once
    const ThreadLimit limit(threadsOf(state));
    std::vector<vec3> out(kPixels);
    timeCalls(state, [&] {
        demodulate(w.current.gi, w.current.albedo, out);
        remodulate(out, w.current.albedo, out);
        benchmark::DoNotOptimize(out.data());
    });
}

constexpr const char* kFootprints[] = {"shadow", "reflection", "ao"};

std::vector<float> footprintOf(int kind, const Frame& f) {
    switch (kind) {
        case 0: return shadowFootprint(kWidth, kHeight, f.penumbraWorld, f.pixelWorld, f.guides.meshId);
        case 1:
            return reflectionFootprint(kWidth, kHeight, f.roughness, f.reflectionHitT, f.pixelWorld, f.guides.meshId);
        default: return aoFootprint(kWidth, kHeight, f.aoHitT, f.aoV, f.pixelWorld, f.guides.meshId);
    }
}

void BM_DenoiseFootprint(benchmark::State& state) {
    const Workload& w = workload();  // built on all threads, once
    const ThreadLimit limit(threadsOf(state));
    const int kind = static_cast<int>(state.range(1));
    state.SetLabel(kFootprints[kind]);
    timeCalls(state, [&] {
        std::vector<float> fp = footprintOf(kind, w.current);
        benchmark::DoNotOptimize(fp.data());
    });
}

// ---------------------------------------------------------------------------
// Stacks, per frame in steady state.

constexpr DenoiseStack kStacks[] = {DenoiseStack::Svgf, DenoiseStack::Shadow, DenoiseStack::Reflection,
                                    DenoiseStack::AmbientOcclusion};

// One stack's filter and frame sequence, shared by its 1-thread and 2-thread
// runs (the filter's output does not depend on the thread count, so the
// 2-thread run simply continues the sequence) and warmed up once, on all
// threads. Warm-up: frames 0..2, after which every pixel that kept its history
// has length >= 4 (temporal variance). They run with atrous.iterations =
// historyTap: the history fed back is the colour after historyTap iterations,
// so it is exactly the one the full stack would keep, for a third of the cost.
struct StackRun {
    DenoiseStack stack;
    StackParams params;
    SvgfFilter filter;
    Frame frame;
    std::vector<vec3> signal, out = std::vector<vec3>(kPixels);
    std::uint32_t nextFrame = 0;

    explicit StackRun(DenoiseStack s) : stack(s), params(StackParams::of(s)), filter(params.svgf) {
        SvgfParams warm = params.svgf;
        warm.atrous.iterations = std::max(1, warm.historyTap);
        filter.setParams(warm);
        for (int k = 0; k < kWarmFrames; ++k) {
            synthesiseNext();
            process();
        }
        filter.setParams(params.svgf);
    }
    // Untimed: the next frame's G-buffer (with its depth gradient) and this stack's signal.
    void synthesiseNext() {
        synthesise(nextFrame++, frame);
        switch (stack) {
            case DenoiseStack::Svgf: signal = frame.gi; break;
            case DenoiseStack::Shadow: signal = grey(frame.shadowV); break;
            case DenoiseStack::Reflection: signal = frame.reflection; break;
            case DenoiseStack::AmbientOcclusion: signal = grey(frame.aoV); break;
        }
    }
    // Timed: the stack's footprint (as EffectLayerDenoiser computes it) and the filter.
    void process() {
        std::vector<float> footprint;
        if (stack == DenoiseStack::Shadow)
            footprint = shadowFootprint(kWidth, kHeight, frame.penumbraWorld, frame.pixelWorld, frame.guides.meshId,
                                        params.footprint);
        else if (stack == DenoiseStack::Reflection)
            footprint = reflectionFootprint(kWidth, kHeight, frame.roughness, frame.reflectionHitT, frame.pixelWorld,
                                            frame.guides.meshId, params.footprint);
        else if (stack == DenoiseStack::AmbientOcclusion)
            footprint = aoFootprint(kWidth, kHeight, frame.aoHitT, frame.aoV, frame.pixelWorld, frame.guides.meshId,
                                    params.footprint);
        filter.filter(frame.guides, signal, out, footprint);
        benchmark::DoNotOptimize(out.data());
    }
};

std::unique_ptr<StackRun> stackRuns[4];

// Thread limit for the timed part only: frame synthesis and warm-up use every core.
class TimedThreads {
public:
    explicit TimedThreads(int threads) : threads_(threads), limit_(std::make_unique<ThreadLimit>(threads)) {}
    void release() { limit_.reset(); }
    void restore() { limit_ = std::make_unique<ThreadLimit>(threads_); }

private:
    int threads_;
    std::unique_ptr<ThreadLimit> limit_;
};

// Times run.process() per frame; synthesising the next frame (untimed) runs
// without the benchmark's thread limit.
template <class Run>
void timeFrames(benchmark::State& state, Run& run) {
    TimedThreads threads(threadsOf(state));
    for (auto _ : state) {
        state.PauseTiming();
        threads.release();
        run.synthesiseNext();
        threads.restore();
        state.ResumeTiming();
        run.process();
    }
}

void BM_DenoiseStack(benchmark::State& state) {
    const int k = static_cast<int>(state.range(1));
    if (!stackRuns[k]) stackRuns[k] = std::make_unique<StackRun>(kStacks[k]);
    StackRun& run = *stackRuns[k];
    state.SetLabel(stackName(run.stack));
    timeFrames(state, run);
    std::size_t valid = 0;
    for (std::uint8_t v : run.filter.reprojectionValid()) valid += v;
    state.counters["valid_fraction"] = static_cast<double>(valid) / static_cast<double>(kPixels);
    state.counters["frame"] = static_cast<double>(run.nextFrame - 1);
    setRate(state);
    if (threadsOf(state) == 2) stackRuns[k].reset();  // registered 1 then 2 threads per stack
}

Image layerImage(const Frame& f) {
    Image img(kWidth, kHeight);
    const auto plane = [&](const std::string& name, auto value) {
        float* c = img.addChannel(name);
        for (std::size_t i = 0; i < kPixels; ++i) c[i] = value(i);
    };
    const GuideBuffers& g = f.guides;
    plane("depth.Z", [&](std::size_t i) { return g.depth[i]; });
    plane("id.mesh", [&](std::size_t i) { return static_cast<float>(g.meshId[i]); });
    plane("motion.X", [&](std::size_t i) { return g.motion[i].x; });
    plane("motion.Y", [&](std::size_t i) { return g.motion[i].y; });
    plane("normal.R", [&](std::size_t i) { return g.normal[i].x; });
    plane("normal.G", [&](std::size_t i) { return g.normal[i].y; });
    plane("normal.B", [&](std::size_t i) { return g.normal[i].z; });
    plane("footprint.pixelWorld", [&](std::size_t i) { return f.pixelWorld[i]; });
    plane("shadow.light0.V", [&](std::size_t i) { return f.shadowV[i]; });
    plane("shadow.light0.penumbra", [&](std::size_t i) { return f.penumbraWorld[i]; });
    plane("ao.V", [&](std::size_t i) { return f.aoV[i]; });
    plane("ao.hitT", [&](std::size_t i) { return f.aoHitT[i]; });
    img.addRgbLayer("gi", f.gi);
    return img;
}

// The effect-layer denoiser and its frame sequence, shared by the 1- and
// 2-thread runs like StackRun; warmed up with frames 0..2 at full cost (its
// stacks' parameters are set inside apply()).
struct LayerRun {
    EffectLayerDenoiser denoiser{{"shadows", "ao", "gi"}};
    Frame frame;
    Image image;
    std::uint32_t nextFrame = 0;
    std::size_t layers = 0;

    LayerRun() {
        for (int k = 0; k < kWarmFrames; ++k) {
            synthesiseNext();
            process();
        }
    }
    void synthesiseNext() {
        synthesise(nextFrame++, frame, false);
        image = layerImage(frame);
    }
    void process() {
        layers = denoiser.apply(image).size();
        benchmark::DoNotOptimize(image.channel("gi.R"));
    }
};

std::unique_ptr<LayerRun> layerRun;

void BM_DenoiseEffectLayers(benchmark::State& state) {
    if (!layerRun) layerRun = std::make_unique<LayerRun>();
    LayerRun& run = *layerRun;
    state.SetLabel("shadow.light0.V, ao.V, gi");
    timeFrames(state, run);
    state.counters["layers"] = static_cast<double>(run.layers);
    setRate(state);
    if (threadsOf(state) == 2) layerRun.reset();
}

// Each stage runs for at least kStageTime (one call is a full 1920x1080 pass,
// 5 to 500 ms); the stacks a fixed number of frames, each preceded by an
// untimed frame synthesis. The whole program takes about 1.5 minutes on 2 cores.
constexpr double kStageTime = 0.5;
constexpr int kStackFrames = 3, kLayerFrames = 3;

}  // namespace

BENCHMARK(BM_DenoiseDepthGradient)->Arg(1)->Arg(2)->MinTime(kStageTime)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseReproject)->Arg(1)->Arg(2)->MinTime(kStageTime)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseReprojectHistory)
    ->Arg(1)
    ->Arg(2)
    ->MinTime(kStageTime)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseTemporal)->Arg(1)->Arg(2)->MinTime(kStageTime)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseVariance)
    ->ArgsProduct({{1, 2}, {1, 0}})
    ->MinTime(kStageTime)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseAtrousIteration)
    ->ArgsProduct({{1, 2}, {1, 16}})
    ->MinTime(kStageTime)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseAtrousFilter)
    ->ArgsProduct({{1, 2}, {1, 5}})
    ->MinTime(kStageTime)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseAtrousRmw)
    ->ArgsProduct({{1, 2}, {0, 1}})
    ->MinTime(kStageTime)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseFireflyClamp)->Arg(1)->Arg(2)->MinTime(kStageTime)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseHistoryClamp)->Arg(1)->Arg(2)->MinTime(kStageTime)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseModulation)->Arg(1)->Arg(2)->MinTime(kStageTime)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseFootprint)
    ->ArgsProduct({{1, 2}, {0, 1, 2}})
    ->MinTime(kStageTime)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseStack)
    ->Args({1, 0})
    ->Args({2, 0})
    ->Args({1, 1})
    ->Args({2, 1})
    ->Args({1, 2})
    ->Args({2, 2})
    ->Args({1, 3})
    ->Args({2, 3})
    ->Iterations(kStackFrames)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseEffectLayers)
    ->Arg(1)
    ->Arg(2)
    ->Iterations(kLayerFrames)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

int main(int argc, char** argv) {
    // The same malloc policy as the rtlab binary, so that the figures are
    // what `rtlab render --denoise` pays per frame.
    retainFreedMemory();
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
