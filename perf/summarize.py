#!/usr/bin/env python3
"""Turns the Google Benchmark JSON files of one `make bench` run into the
ratios the issues ask for, written to OUT_DIR/summary.json and printed."""
import json, pathlib, sys

out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "out/bench")
times, rates, model = {}, {}, {}
for f in sorted(out.glob("*.json")):
    if f.name == "summary.json":
        continue
    for b in json.loads(f.read_text()).get("benchmarks", []):
        if b.get("run_type", "iteration") != "iteration":
            continue
        times[b["name"]] = b["real_time"]
        if "rays_per_s" in b:
            rates[b["name"]] = b["rays_per_s"]
        if b["name"].startswith("BM_RtCoreTimingModel/"):
            model[b.get("label", b["name"])] = {k: b[k] for k in ("cyclesPerRay", "meanLatency", "nodeVisitsPerRay",
                                                                  "triangleTestsPerRay", "cacheHitRate", "simdEfficiency") if k in b}

def ratio(num, den, table):
    return table[num] / table[den] if num in table and den in table and table[den] else None

def b(name, threads, watertight):
    return f"{name}/{threads}/{watertight}/min_time:1.000/real_time"

summary = {
    "pipeline_vs_raw_embree_throughput_1t": ratio(b("BM_PipelinePacket", 1, 1), b("BM_RawIntersect8", 1, 1), rates),
    "pipeline_vs_raw_embree_throughput_2t": ratio(b("BM_PipelinePacket", 2, 1), b("BM_RawIntersect8", 2, 1), rates),
    "pipeline_vs_raw_embree_throughput_1t_native_triangles": ratio(b("BM_PipelinePacket", 1, 0), b("BM_RawIntersect8", 1, 0), rates),
    "watertight_vs_native_raw_embree_1t": ratio(b("BM_RawIntersect8", 1, 1), b("BM_RawIntersect8", 1, 0), rates),
    "packet_vs_single_ray_throughput_1t": ratio(b("BM_PipelinePacket", 1, 1), b("BM_PipelineSingleRay", 1, 1), rates),
    "pipeline_packet_2t_vs_1t": ratio(b("BM_PipelinePacket", 2, 1), b("BM_PipelinePacket", 1, 1), rates),
    "raw_embree_2t_vs_1t": ratio(b("BM_RawIntersect8", 2, 1), b("BM_RawIntersect8", 1, 1), rates),
    "refit_vs_rebuild_time_1M": ratio("BM_Refit1M/1/min_time:2.000/real_time", "BM_Rebuild1M/1/min_time:2.000/real_time", times),
    "refit_vs_rebuild_time_1M_native_triangles": ratio("BM_Refit1M/0/min_time:2.000/real_time", "BM_Rebuild1M/0/min_time:2.000/real_time", times),
    "one_moves_vs_full_build_1000": ratio("BM_OneMoves1000/min_time:1.000/real_time", "BM_FullBuild1000/min_time:1.000/real_time", times),
    # RT-core model host speed: simulated rays/s over Embree rtcIntersect1 rays/s, one thread (goal >= 0.125).
    "rtcore_speed_vs_embree_primary": ratio("BM_RtCoreTimingModel/0/0/min_time:1.000/real_time", "BM_EmbreeIntersect1/0/1/min_time:1.000/real_time", rates),
    "rtcore_speed_vs_embree_bounce": ratio("BM_RtCoreTimingModel/1/0/min_time:1.000/real_time", "BM_EmbreeIntersect1/1/1/min_time:1.000/real_time", rates),
    "rtcore_speed_vs_embree_primary_native_triangles": ratio("BM_RtCoreTimingModel/0/0/min_time:1.000/real_time", "BM_EmbreeIntersect1/0/0/min_time:1.000/real_time", rates),
    "rtcore_speed_vs_embree_bounce_native_triangles": ratio("BM_RtCoreTimingModel/1/0/min_time:1.000/real_time", "BM_EmbreeIntersect1/1/0/min_time:1.000/real_time", rates),
    "rtcore_functional_vs_embree_primary": ratio("BM_RtCoreFunctional/0/min_time:1.000/real_time", "BM_EmbreeIntersect1/0/1/min_time:1.000/real_time", rates),
    "rtcore_functional_vs_embree_bounce": ratio("BM_RtCoreFunctional/1/min_time:1.000/real_time", "BM_EmbreeIntersect1/1/1/min_time:1.000/real_time", rates),
}
(out / "summary.json").write_text(json.dumps({**summary, "rtcore_model_showcase": model}, indent=2) + "\n")
for k, v in summary.items():
    print(f"{k}: {v:.4f}" if v is not None else f"{k}: (missing)")
for label, figures in model.items():
    print(f"rtcore model, showcase {label}: " + ", ".join(f"{k} {v:.3f}" for k, v in figures.items()))
