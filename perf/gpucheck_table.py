#!/usr/bin/env python3
"""The GPU check's table (docs/validation.md) from perf/gpucheck.sh's output.

    perf/gpucheck_table.py OUT [--models DIR]

Reads OUT/<workload>.{traverse,io}.csv (Nsight Compute), OUT/<workload>.run.json
(the CUDA program) and the model's prediction, OUT/<workload>.model.json or,
with --models DIR, DIR/<workload>/model.json (predictions made again with other
model parameters: the measured files are kept). Writes OUT/gpucheck.json and
prints a Markdown table. The GPU's counts are the traversal kernel's minus the
same kernel's over an empty scene (the rays read, the answers written), so what remains is
the BVH fetch stream; the model counts the same fetches (docs/validation.md,
"Counting the same thing")."""
import csv
import json
import pathlib
import sys


def ncu_metrics(path):
    values = {}
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(f)]
    header = next((i for i, r in enumerate(rows) if "Metric Name" in r), None)
    if header is None:
        return values
    name_at, value_at = rows[header].index("Metric Name"), rows[header].index("Metric Value")
    for r in rows[header + 1:]:
        if len(r) > value_at:
            try:
                values[r[name_at]] = float(r[value_at].replace(",", ""))
            except ValueError:
                values[r[name_at]] = r[value_at]
    return values


def main():
    out = pathlib.Path(sys.argv[1])
    models = pathlib.Path(sys.argv[sys.argv.index("--models") + 1]) if "--models" in sys.argv else None
    rows = []
    for run_path in sorted(out.glob("*.run.json")):
        name = run_path.name[: -len(".run.json")]
        run = json.loads(run_path.read_text())
        model_path = models / name / "model.json" if models else out / f"{name}.model.json"
        model = json.loads(model_path.read_text())
        t, io = ncu_metrics(out / f"{name}.traverse.csv"), ncu_metrics(out / f"{name}.io.csv")
        for metrics, kind in ((t, "traverse"), (io, "io")):  # GPUCHECK_EXTRA_METRICS (rows without a header)
            extra = out / f"{name}.{kind}.extra.csv"
            if extra.exists():
                for r in csv.reader(extra.read_text().splitlines()):
                    if len(r) >= 3:
                        try:
                            metrics[r[-3]] = float(r[-1].replace(",", ""))
                        except ValueError:
                            pass
        rays = run["rays"]

        def net(metric):
            if metric not in t or metric not in io:
                sys.exit(f"gpucheck_table: {name}: ncu did not report {metric}")
            return t[metric] - io[metric]

        l1_sectors = net("l1tex__t_sectors_pipe_lsu_mem_global_op_ld.sum")
        l1_hits = net("l1tex__t_sectors_pipe_lsu_mem_global_op_ld_lookup_hit.sum")
        l1_misses = net("l1tex__t_sectors_pipe_lsu_mem_global_op_ld_lookup_miss.sum")
        l2_sectors = net("lts__t_sectors_srcunit_tex_op_read.sum")
        l2_hits = net("lts__t_sectors_srcunit_tex_op_read_lookup_hit.sum")
        dram = net("dram__bytes_read.sum")
        fabric = net("lts__t_sectors_srcunit_ltcfabric_op_read.sum")
        fabric_hits = net("lts__t_sectors_srcunit_ltcfabric_op_read_lookup_hit.sum")
        # The model's L2 is one cache whose misses each read l2.lineBytes from DRAM: its hit rate is
        # 1 - (DRAM bytes per L2 request) / l2.lineBytes, and so is the GPU's counted the same way
        # (docs/validation.md, "Counting the same thing").
        l2_fill = model["config"]["l2"]["lineBytes"]
        thread_sectors = model["fetch"]["sectors"]
        p = model["predicted"]
        cache = model["config"]["cache"]
        fill_bytes = cache.get("sectorBytes") or cache["lineBytes"]  # the L1's unit of lookup and fill
        row = {
            "workload": name,
            "rays": rays,
            "raysPerSecond": run["raysPerSecond"],
            "mismatches": run["mismatches"],
            "measured": {
                "l1SectorsCoalesced": l1_sectors,
                "l1HitRateCoalesced": l1_hits / l1_sectors if l1_sectors else None,
                "l1MissSectorsPerRay": l1_misses / rays,
                "l1HitRate": 1.0 - l1_misses / thread_sectors if thread_sectors else None,
                "l2HitRate": 1.0 - dram / l2_fill / l2_sectors if l2_sectors else None,
                "l2NearHitRate": l2_hits / l2_sectors if l2_sectors else None,
                "l2FabricSectorsPerRay": fabric / rays,
                "l2FabricHitRate": fabric_hits / fabric if fabric else None,
                "l2SectorsPerRay": l2_sectors / rays,
                "dramBytesPerRay": dram / rays,
                "sharedMemConfigBytes": t.get("launch__shared_mem_config_size"),
                "warpsActivePerCycle": t.get("sm__warps_active.avg.per_cycle_active"),
                "registersPerThread": t.get("launch__registers_per_thread"),
                "smClockHz": t.get("sm__cycles_elapsed.avg.per_second"),
                "kernelSeconds": t.get("gpu__time_duration.sum"),
                "raw": {"traverse": t, "io": io},
            },
            "predicted": {
                "l1HitRate": p["l1"]["hitRate"],
                "l1HitRateWithoutPending": p["l1"]["hitRateWithoutPending"],
                "l1MissSectorsPerRay": p["l1"]["misses"] * fill_bytes / 32 / rays,
                "l2HitRate": p["l2"]["hitRate"],
                "l2HitRateWithoutPending": p["l2"]["hitRateWithoutPending"],
                "dramBytesPerRay": p["dram"]["bytesPerRay"],
            },
            "threadSectorsPerRay": thread_sectors / rays,
        }
        m, q = row["measured"], row["predicted"]
        row["error"] = {
            "l1HitRatePoints": None if m["l1HitRate"] is None else 100 * (q["l1HitRate"] - m["l1HitRate"]),
            "l2HitRatePoints": None if m["l2HitRate"] is None else 100 * (q["l2HitRate"] - m["l2HitRate"]),
            "l2NearHitRatePoints": None if m["l2NearHitRate"] is None else 100 * (q["l2HitRate"] - m["l2NearHitRate"]),
            "dramBytesPerRayRelative": (q["dramBytesPerRay"] - m["dramBytesPerRay"]) / m["dramBytesPerRay"]
            if m["dramBytesPerRay"] else None,
        }
        rows.append(row)
    (out / "gpucheck.json").write_text(json.dumps(rows, indent=2) + "\n")

    def pct(v):
        return "n/a" if v is None else f"{100 * v:.1f}%"

    def pts(v):
        return "n/a" if v is None else f"{v:+.1f}"

    print("| workload | rays | GPU rays/s | L1 hit (GPU / model, pts) | L2 hit (GPU / model, pts) "
          "| DRAM B/ray (GPU / model, err) | ncu L1 hit (coalesced) | ncu L2 hit, near partition (pts) |")
    print("|---|---:|---:|---|---|---|---:|---:|")
    for r in rows:
        m, q, e = r["measured"], r["predicted"], r["error"]
        dram_err = "n/a" if e["dramBytesPerRayRelative"] is None else f"{100 * e['dramBytesPerRayRelative']:+.0f}%"
        print(f"| {r['workload']} | {r['rays']} | {r['raysPerSecond']:.3g} "
              f"| {pct(m['l1HitRate'])} / {pct(q['l1HitRate'])} ({pts(e['l1HitRatePoints'])}) "
              f"| {pct(m['l2HitRate'])} / {pct(q['l2HitRate'])} ({pts(e['l2HitRatePoints'])}) "
              f"| {m['dramBytesPerRay']:.0f} / {q['dramBytesPerRay']:.0f} ({dram_err}) "
              f"| {pct(m['l1HitRateCoalesced'])} | {pct(m['l2NearHitRate'])} ({pts(e['l2NearHitRatePoints'])}) |")


if __name__ == "__main__":
    main()
