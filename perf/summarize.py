#!/usr/bin/env python3
"""Turns the Google Benchmark JSON files of one `make bench` run into the
ratios the issues ask for, written to OUT_DIR/summary.json and printed.
Where a benchmark ran several repetitions, its fastest one counts."""
import json, math, pathlib, re, sys

out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "out/bench")
times, rates, model, cpu_over_wall = {}, {}, {}, {}
terrain_scaling = []  # perf/scalable_scenes.cpp: one entry per terrain size
denoise_times = {}  # (benchmark, args...) -> ms, from perf/denoise_speed.cpp
frame_cost = {}  # perf/frame_cost.cpp: effect -> size -> {"render": ms, "denoise": ms}
FRAME_EFFECTS, FRAME_SIZES = ("shadows", "reflections", "ao", "gi"), ("320x180", "480x270")
for f in sorted(out.glob("*.json")):
    if f.name == "summary.json":
        continue
    for b in json.loads(f.read_text()).get("benchmarks", []):
        if b.get("run_type", "iteration") != "iteration":
            continue
        # Repeated runs (--benchmark_repetitions, interleaved): the fastest
        # repetition counts, as the least disturbed by a noisy machine.
        times[b["name"]] = min(b["real_time"], times.get(b["name"], float("inf")))
        if "rays_per_s" in b:
            rates[b["name"]] = max(b["rays_per_s"], rates.get(b["name"], 0.0))
        if b["name"].startswith("BM_RtCoreGpu8/") and b.get("real_time"):
            # CPU time (the process's, all threads) over wall time of the fastest repetition
            if b["real_time"] <= times[b["name"]]:
                cpu_over_wall[b["name"]] = b["cpu_time"] / b["real_time"]
        if b["name"].startswith("BM_Denoise"):
            m = re.match(r"(BM_Denoise\w+)((?:/\d+)*)", b["name"])
            scale = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}[b.get("time_unit", "ns")]
            denoise_times[(m.group(1),) + tuple(int(a) for a in m.group(2).split("/")[1:])] = b["real_time"] * scale
        m = re.match(r"BM_(Render|Denoise)Frame/(\d+)/(\d+)/", b["name"])
        if m:
            scale = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}[b.get("time_unit", "ns")]
            part = frame_cost.setdefault(FRAME_EFFECTS[int(m.group(2))], {}).setdefault(FRAME_SIZES[int(m.group(3))], {})
            key = m.group(1).lower()
            part[key] = min(b["real_time"] * scale, part.get(key, float("inf")))
        if b["name"].startswith("BM_TerrainAccelScaling/"):
            terrain_scaling.append({k: b[k] for k in ("uniqueTriangles", "buildMs", "embreeBytes", "clusterBytes",
                                                       "bytesPerTriangle") if k in b})
        if b["name"].startswith("BM_RtCoreTimingModel/"):
            model[b.get("label", b["name"])] = {k: b[k] for k in ("cyclesPerRay", "meanLatency", "nodeVisitsPerRay",
                                                                  "triangleTestsPerRay", "cacheHitRate", "simdEfficiency") if k in b}

def ratio(num, den, table):
    return table[num] / table[den] if num in table and den in table and table[den] else None

def gpu8(workload, rays, threads):  # perf/rtcore_speed.cpp BM_RtCoreGpu8 (threads 0 = the serial model)
    return f"BM_RtCoreGpu8/{workload}/{rays}/{threads}/min_time:1.000/process_time/real_time"

def b(name, threads, watertight):
    return f"{name}/{threads}/{watertight}/min_time:1.000/real_time"

summary = {
    "pipeline_vs_raw_embree_throughput_1t": ratio(b("BM_PipelinePacket", 1, 1), b("BM_RawIntersect8", 1, 1), rates),
    "pipeline_vs_raw_embree_throughput_2t": ratio(b("BM_PipelinePacket", 2, 1), b("BM_RawIntersect8", 2, 1), rates),
    "pipeline_vs_raw_embree_throughput_1t_native_triangles": ratio(b("BM_PipelinePacket", 1, 0), b("BM_RawIntersect8", 1, 0), rates),
    "watertight_vs_native_raw_embree_1t": ratio(b("BM_RawIntersect8", 1, 1), b("BM_RawIntersect8", 1, 0), rates),
    # Diffuse bounce rays (incoherent packets), one thread (issue goal: >= 0.8 for both).
    "watertight_vs_native_raw_embree_bounce_1t": ratio("BM_RawIntersect8Bounce/1/min_time:1.000/real_time", "BM_RawIntersect8Bounce/0/min_time:1.000/real_time", rates),
    # Native triangles through the same query API (tracer/ray_query.hpp) as the watertight ones: the
    # triangles' share of the gap; the key above is the goal.
    "watertight_vs_native_query_api_bounce_1t": ratio("BM_RawIntersect8Bounce/1/min_time:1.000/real_time", "BM_RawIntersect8Bounce/2/min_time:1.000/real_time", rates),
    "native_query_api_vs_raw_embree_bounce_1t": ratio("BM_RawIntersect8Bounce/2/min_time:1.000/real_time", "BM_RawIntersect8Bounce/0/min_time:1.000/real_time", rates),
    "packet_vs_single_ray_throughput_1t": ratio(b("BM_PipelinePacket", 1, 1), b("BM_PipelineSingleRay", 1, 1), rates),
    "pipeline_packet_2t_vs_1t": ratio(b("BM_PipelinePacket", 2, 1), b("BM_PipelinePacket", 1, 1), rates),
    "raw_embree_2t_vs_1t": ratio(b("BM_RawIntersect8", 2, 1), b("BM_RawIntersect8", 1, 1), rates),
    "refit_vs_rebuild_time_1M": ratio("BM_Refit1M/1/min_time:2.000/real_time", "BM_Rebuild1M/1/min_time:2.000/real_time", times),
    "refit_vs_rebuild_time_1M_native_triangles": ratio("BM_Refit1M/0/min_time:2.000/real_time", "BM_Rebuild1M/0/min_time:2.000/real_time", times),
    "one_moves_vs_full_build_1000": ratio("BM_OneMoves1000/min_time:1.000/real_time", "BM_FullBuild1000/min_time:1.000/real_time", times),
    # rtlab replay on Embree over raw rtcIntersect8/rtcOccluded8 on the same recorded rays, one thread (goal >= 0.8).
    "replay_vs_raw_embree_1t": ratio("BM_ReplayEmbree/-1/min_time:1.000/real_time", "BM_RawEmbreeSameRays/-1/min_time:1.000/real_time", rates),
    # The same rays through tracer::queryClosest8 / queryAny8: what the watertight triangles cost, apart from replay.
    "query_api_vs_raw_embree_recorded_rays_1t": ratio("BM_QueryApiSameRays/-1/min_time:1.000/real_time", "BM_RawEmbreeSameRays/-1/min_time:1.000/real_time", rates),
    **{f"replay_vs_raw_embree_1t_{name}": ratio(f"BM_ReplayEmbree/{t}/min_time:1.000/real_time", f"BM_RawEmbreeSameRays/{t}/min_time:1.000/real_time", rates)
       for t, name in ((0, "primary"), (1, "shadow"), (3, "ao"), (6, "path_bounce"))},
    # RT-core model host speed: simulated rays/s over Embree rtcIntersect1 rays/s, one thread (goal >= 0.125).
    "rtcore_speed_vs_embree_primary": ratio("BM_RtCoreTimingModel/0/0/min_time:1.000/real_time", "BM_EmbreeIntersect1/0/1/min_time:1.000/real_time", rates),
    "rtcore_speed_vs_embree_bounce": ratio("BM_RtCoreTimingModel/1/0/min_time:1.000/real_time", "BM_EmbreeIntersect1/1/1/min_time:1.000/real_time", rates),
    "rtcore_speed_vs_embree_primary_native_triangles": ratio("BM_RtCoreTimingModel/0/0/min_time:1.000/real_time", "BM_EmbreeIntersect1/0/0/min_time:1.000/real_time", rates),
    "rtcore_speed_vs_embree_bounce_native_triangles": ratio("BM_RtCoreTimingModel/1/0/min_time:1.000/real_time", "BM_EmbreeIntersect1/1/0/min_time:1.000/real_time", rates),
    # GPU level (issue 14): 8 simulated cores with the L2 in mode cache, one host thread (goal >= 0.1).
    "rtcore_speed_gpu8_vs_embree_showcase_primary": ratio(gpu8(0, 0, 1), "BM_EmbreeIntersect1/0/1/min_time:1.000/real_time", rates),
    "rtcore_speed_gpu8_vs_embree_showcase_bounce": ratio(gpu8(0, 1, 1), "BM_EmbreeIntersect1/1/1/min_time:1.000/real_time", rates),
    "rtcore_speed_gpu8_vs_embree_terrain1m_primary": ratio(gpu8(1, 0, 1), "BM_EmbreeIntersect1Scene/1/0/min_time:1.000/real_time", rates),
    "rtcore_speed_gpu8_vs_embree_terrain1m_bounce": ratio(gpu8(1, 1, 1), "BM_EmbreeIntersect1Scene/1/1/min_time:1.000/real_time", rates),
    # Host-parallel epochs: 2 host threads over 1 (goal >= 1.6), and over the serial model (one thread, cycle by cycle).
    **{f"rtcore_speed_gpu8_2t_vs_1t_{scene}_{rays}": ratio(gpu8(w, r, 2), gpu8(w, r, 1), rates)
       for w, scene in ((0, "showcase"), (1, "terrain1m")) for r, rays in ((0, "primary"), (1, "bounce"))},
    **{f"rtcore_speed_gpu8_2t_vs_serial_{scene}_{rays}": ratio(gpu8(w, r, 2), gpu8(w, r, 0), rates)
       for w, scene in ((0, "showcase"), (1, "terrain1m")) for r, rays in ((0, "primary"), (1, "bounce"))},
    # Process CPU time over wall time of the 2-thread runs (2.0 = both threads busy throughout).
    **{f"rtcore_gpu8_2t_cpu_vs_wall_{scene}_{rays}": cpu_over_wall.get(gpu8(w, r, 2))
       for w, scene in ((0, "showcase"), (1, "terrain1m")) for r, rays in ((0, "primary"), (1, "bounce"))},
    # Launch level (issue 31): 30 cores (rtx2060-like), one launch of terrain 1M primary + bounce rays.
    "rtcore_speed_launch30_vs_embree_terrain1m": ratio("BM_RtCoreLaunch30/1/min_time:1.000/process_time/real_time", "BM_EmbreeIntersect1Launch/min_time:1.000/real_time", rates),
    "rtcore_speed_launch30_2t_vs_1t_terrain1m": ratio("BM_RtCoreLaunch30/2/min_time:1.000/process_time/real_time", "BM_RtCoreLaunch30/1/min_time:1.000/process_time/real_time", rates),
    "rtcore_functional_vs_embree_primary": ratio("BM_RtCoreFunctional/0/min_time:1.000/real_time", "BM_EmbreeIntersect1/0/1/min_time:1.000/real_time", rates),
    "rtcore_functional_vs_embree_bounce": ratio("BM_RtCoreFunctional/1/min_time:1.000/real_time", "BM_EmbreeIntersect1/1/1/min_time:1.000/real_time", rates),
}

# Denoiser at 1920x1080 (perf/denoise_speed.cpp): ms per stage and per stack
# at 1 and 2 threads (first benchmark argument), and one a-trous iteration
# against a read-modify-write pass over the same 60 bytes per pixel.
DENOISE_STAGES = [  # (summary key, benchmark, further arguments)
    ("depth_gradient", "BM_DenoiseDepthGradient", ()),
    ("reproject", "BM_DenoiseReproject", ()),
    ("reproject_history", "BM_DenoiseReprojectHistory", ()),
    ("temporal_accumulation", "BM_DenoiseTemporal", ()),
    ("variance_warm_history", "BM_DenoiseVariance", (1,)),
    ("variance_history_1", "BM_DenoiseVariance", (0,)),
    ("atrous_iteration_step1", "BM_DenoiseAtrousIteration", (1,)),
    ("atrous_iteration_step16", "BM_DenoiseAtrousIteration", (16,)),
    ("atrous_filter_1_iteration", "BM_DenoiseAtrousFilter", (1,)),
    ("atrous_filter_5_iterations", "BM_DenoiseAtrousFilter", (5,)),
    ("firefly_clamp", "BM_DenoiseFireflyClamp", ()),
    ("history_clamp", "BM_DenoiseHistoryClamp", ()),
    ("demodulate_remodulate", "BM_DenoiseModulation", ()),
    ("footprint_shadow", "BM_DenoiseFootprint", (0,)),
    ("footprint_reflection", "BM_DenoiseFootprint", (1,)),
    ("footprint_ao", "BM_DenoiseFootprint", (2,)),
]
DENOISE_RMW = [  # the memory-bound reference of one a-trous iteration, two layouts of the same bytes
    ("api_buffers", "BM_DenoiseAtrousRmw", (0,)),
    ("soa_planes", "BM_DenoiseAtrousRmw", (1,)),
]
DENOISE_STACKS = [
    ("svgf", "BM_DenoiseStack", (0,)),
    ("shadow", "BM_DenoiseStack", (1,)),
    ("reflection", "BM_DenoiseStack", (2,)),
    ("ao", "BM_DenoiseStack", (3,)),
    ("effect_layers_shadow_ao_gi", "BM_DenoiseEffectLayers", ()),
]
THREADS = (1, 2)

def denoise_ms(bench, threads, args):
    return denoise_times.get((bench, threads) + args)

def per_thread(table):
    return {key: {f"{t}t": denoise_ms(bench, t, args) for t in THREADS} for key, bench, args in table}

def div(a, b):
    return a / b if a is not None and b else None

denoise = None
if denoise_times:
    stages, stacks, rmw = per_thread(DENOISE_STAGES), per_thread(DENOISE_STACKS), per_thread(DENOISE_RMW)
    ratios = {}
    for t in THREADS:
        f1, f5 = denoise_ms("BM_DenoiseAtrousFilter", t, (1,)), denoise_ms("BM_DenoiseAtrousFilter", t, (5,))
        in_filter = (f5 - f1) / 4 if f1 is not None and f5 is not None else None
        stages.setdefault("atrous_iteration_in_filter", {})[f"{t}t"] = in_filter
        rmw_api, rmw_soa = denoise_ms("BM_DenoiseAtrousRmw", t, (0,)), denoise_ms("BM_DenoiseAtrousRmw", t, (1,))
        ratios[f"{t}t"] = {
            # atrousIteration() (the public call: converts vec3 colour and the guides to planes every call)
            # over the RMW pass on the buffers it receives.
            "atrous_iteration_step1_vs_rmw": div(denoise_ms("BM_DenoiseAtrousIteration", t, (1,)), rmw_api),
            "atrous_iteration_step16_vs_rmw": div(denoise_ms("BM_DenoiseAtrousIteration", t, (16,)), rmw_api),
            # One iteration inside atrousFilter ((5 - 1 iterations) / 4: steps 2..16) over the RMW pass on
            # the structure-of-arrays planes it works on.
            "atrous_in_filter_iteration_vs_rmw": div(in_filter, rmw_soa),
        }
    denoise = {"resolution": "1920x1080", "stages_ms": stages, "stacks_ms": stacks, "rmw_reference_ms": rmw,
               "atrous_vs_rmw": ratios}

def loglog_slope(points):
    """Least-squares slope of log(y) over log(x): 1 = linear in N."""
    pts = [(math.log(x), math.log(y)) for x, y in points if x > 0 and y > 0]
    if len(pts) < 2:
        return None
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    sxx = sum((p[0] - mx) ** 2 for p in pts)
    return sum((p[0] - mx) * (p[1] - my) for p in pts) / sxx if sxx else None

scaling = None
if terrain_scaling:
    terrain_scaling.sort(key=lambda e: e.get("uniqueTriangles", 0))
    scaling = {
        "sizes": terrain_scaling,
        "build_ms_loglog_slope": loglog_slope([(e["uniqueTriangles"], e["buildMs"]) for e in terrain_scaling]),
        "memory_bytes_loglog_slope": loglog_slope(
            [(e["uniqueTriangles"], e["embreeBytes"] + e["clusterBytes"]) for e in terrain_scaling]),
    }

(out / "summary.json").write_text(json.dumps({**summary, "rtcore_model_showcase": model, "denoise": denoise,
                                              "terrain_accel_scaling": scaling, "frame_cost_ms": frame_cost},
                                             indent=2) + "\n")
for k, v in summary.items():
    print(f"{k}: {v:.4f}" if v is not None else f"{k}: (missing)")
for label, figures in model.items():
    print(f"rtcore model, showcase {label}: " + ", ".join(f"{k} {v:.3f}" for k, v in figures.items()))

def fmt(v, spec):
    return format(v, spec) if v is not None else "(missing)"

if denoise is None:
    print("denoise: (missing)")
else:
    print("denoise 1920x1080, ms at 1 / 2 threads:")
    for section, name in (("stages_ms", "stage"), ("stacks_ms", "stack"), ("rmw_reference_ms", "rmw reference")):
        for key, by_threads in denoise[section].items():
            print(f"  {name} {key}: " + " / ".join(fmt(by_threads[f'{t}t'], '.2f') for t in THREADS))
    for key in denoise["atrous_vs_rmw"]["1t"]:
        print(f"denoise {key}: " + ", ".join(f"{t}t " + fmt(denoise['atrous_vs_rmw'][f'{t}t'][key], '.2f') for t in THREADS))
if scaling:
    print("terrain acceleration structures, 1e4..4e6 triangles (perf/scalable_scenes.cpp):")
    for e in scaling["sizes"]:
        print(f"  {int(e['uniqueTriangles'])} triangles: build {e['buildMs']:.1f} ms, "
              f"{e['bytesPerTriangle']:.1f} bytes/triangle (Embree {int(e['embreeBytes'])}, clusters {int(e['clusterBytes'])})")
    print(f"  log-log slope: build time {scaling['build_ms_loglog_slope']:.3f}, memory {scaling['memory_bytes_loglog_slope']:.3f}")
if frame_cost:
    print("one showcase frame at 1 spp, render + a fresh denoiser, ms (perf/frame_cost.cpp; what rtlab converge times):")
    for effect, sizes in frame_cost.items():
        for size, parts in sizes.items():
            print(f"  {effect} {size}: render {fmt(parts.get('render'), '.1f')}, denoise {fmt(parts.get('denoise'), '.1f')}")
