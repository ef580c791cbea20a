#!/usr/bin/env python3
"""The GPU study of docs/studies/gpu-study.md: four study files run by
`rtlab sweep` (the front door users run), their reports, and the tables of
the page regenerated from the results.

    scripts/gpu_study.py RTLAB [--out DIR] [--jobs N] [--reuse] [--check]

  RTLAB    the rtlab executable (make gpu-study passes build/release/apps/rtlab)
  --out    where the sweeps write (default out/gpu-study); each study in DIR/NAME
  --jobs   points run at once (default 2)
  --reuse  do not run the sweeps again (they resume anyway): tables from DIR only
  --check  run the sweeps afresh in a temporary directory (with --reuse: use
           the results in --out) and compare the tables with the page instead of rewriting it (exit 1
           with a diff on a difference; ctest docs.gpuStudy); no reports, no plots

Each table of docs/studies/gpu-study.md follows a line
    <!-- gpu-study: NAME -->
and runs to the next blank line; this script rewrites it. The plots are the
reports' own PNGs, copied to docs/studies/gpu-*.png.
"""
import json
import re
import os
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PAGE = os.path.join(ROOT, "docs", "studies", "gpu-study.md")
STUDIES = ["gpu-scaling", "gpu-memory", "gpu-policies", "gpu-service-order"]
POLICIES = ["fifo", "oldestFirst", "treelet", "treeletPrefetch", "rayOrder=directionOrigin"]


def policy_of(row):
    o = row["overrides"]
    return o["scheduler.policy"] if "scheduler.policy" in o else "rayOrder=" + o["gpu.rayOrder"]
NOISE = 0.01  # a policy's effect smaller than 1 % of cycles is reported as within noise


def run(argv):
    print("+ " + " ".join(argv), flush=True)
    subprocess.run(argv, check=True)


def rows(directory):
    if not os.path.exists(os.path.join(directory, "results.jsonl")):
        sys.exit(f"gpu_study: no results in {directory} (run without --reuse first)")
    out = []
    with open(os.path.join(directory, "results.jsonl")) as f:
        for line in f:
            row = json.loads(line)
            with open(os.path.join(directory, "points", row["id"], "stats.json")) as s:
                row["stats"] = json.load(s)
            out.append(row)
    return out


def thousands(v):
    return f"{int(v):,}"


def short(workload):
    return (workload.replace("builtin:", "").replace("?triangles=1000000", " 1M").replace("?instances=10000", " 10k")
            .replace("&seed=", ", seed "))


def launches(row):
    frame = row["stats"]["frames"][0]
    return list(zip(frame["launchPasses"], frame["rtcore"]["backend"]["launches"]))


KINDS = ["traversalUnits", "triangleUnits", "scheduler", "raySlots", "memoryPort", "l2Bank", "dramChannel"]


def utilization_table(scaling):
    lines = ["| workload | launch (pass) | rays | cycles | busiest resource | its utilization | "
             + " | ".join(KINDS) + " |",
             "|---|---|---:|---:|---|---:|" + "---:|" * len(KINDS)]
    for row in scaling:
        if row["overrides"]["gpu.cores"] != 30:
            continue
        for label, launch in launches(row):
            kinds = launch["busiestByKind"]
            lines.append(f"| {short(row['workload'])} | {label} | {thousands(launch['rays'])} | "
                         f"{thousands(launch['cycles'])} | {launch['busiest']['resource']} | "
                         f"{launch['busiest']['utilization']:.2f} | "
                         + " | ".join(f"{kinds.get(k, 0.0):.2f}" for k in KINDS) + " |")
    return lines


def shared_busiest(row):
    """The busiest shared resource (an L2 bank or a DRAM channel) over the frame's launches, cycle-weighted."""
    best = ("none", 0.0)
    total = sum(l["cycles"] for _, l in launches(row)) or 1
    for kind in ("l2Bank", "dramChannel"):
        u = sum(l["busiestByKind"].get(kind, 0.0) * l["cycles"] for _, l in launches(row)) / total
        if u > best[1]:
            best = (kind, u)
    return best


def scaling_table(scaling):
    lines = ["| workload | 1 core | 8 cores | 30 cores | 1 → 8 | 8 → 30 | busiest shared resource at 8 cores | verdict |",
             "|---|---:|---:|---:|---:|---:|---|---|"]
    for workload in dict.fromkeys(r["workload"] for r in scaling):
        by = {r["overrides"]["gpu.cores"]: r for r in scaling if r["workload"] == workload}
        c = {k: by[k]["metrics"]["cycles"] for k in (1, 8, 30)}
        kind, u = shared_busiest(by[8])
        s18 = c[1] / c[8]
        verdict = ("≥ 5×" if s18 >= 5 else
                   f"< 5×: {kind} {u:.2f} busy (≥ 0.8: the shared resource bounds it)" if u >= 0.8 else
                   f"< 5× with no shared resource ≥ 0.8 busy: a miss")
        lines.append(f"| {short(workload)} | {thousands(c[1])} | {thousands(c[8])} | {thousands(c[30])} | "
                     f"{s18:.2f}× | {c[8] / c[30]:.2f}× | {kind} {u:.2f} | {verdict} |")
    return lines


def memory_table(memory):
    base = next(r for r in memory if r["overrides"].get("l2.sizeBytes") == 3145728)["metrics"]["cycles"]
    lines = ["| parameter | value | cycles | vs default | L2 hit rate | DRAM bytes | busiest resource (pathtrace launch) |",
             "|---|---|---:|---:|---:|---:|---|"]
    for row in memory:
        (key, value), = row["overrides"].items()
        shown = f"{value // 1024} KiB" if key == "l2.sizeBytes" and value < 1 << 20 else \
            f"{value / (1 << 20):g} MiB" if key == "l2.sizeBytes" else f"{value} B/cycle per channel"
        last = launches(row)[-1][1]["busiest"]
        m = row["metrics"]
        default = (key == "l2.sizeBytes" and value == 3145728)
        lines.append(f"| {key} | {shown}{' (default)' if default else ''} | {thousands(m['cycles'])} | "
                     f"{(m['cycles'] / base - 1) * 100:+.1f} % | {m['l2HitRate']:.3f} | {thousands(m['dramBytes'])} | "
                     f"{last['resource']} {last['utilization']:.2f} |")
    # The default DRAM bandwidth is the 3 MiB row.
    return lines


def policy_table(policies):
    lines = ["| workload | " + " | ".join(POLICIES) + " |", "|---|" + "---:|" * len(POLICIES)]
    effects = {}
    for workload in dict.fromkeys(r["workload"] for r in policies):
        by = {policy_of(r): r["metrics"]["cycles"] for r in policies if r["workload"] == workload}
        cells = [thousands(by["fifo"])]
        for p in POLICIES[1:]:
            change = by[p] / by["fifo"] - 1
            cells.append(f"{thousands(by[p])} ({change * 100:+.1f} %)")
            scene = workload.split("&")[0]
            effects.setdefault((scene, p), []).append(change)
        lines.append(f"| {short(workload)} | " + " | ".join(cells) + " |")
    summary = ["| scene | policy | change in cycles vs fifo, 3 seeds | verdict |", "|---|---|---|---|"]
    for (scene, p), changes in effects.items():
        signs = {c > 0 for c in changes}
        verdict = ("within noise (every change under 1 %)" if all(abs(c) < NOISE for c in changes) else
                   ("slower on all three" if signs == {True} else "faster on all three") if len(signs) == 1 else
                   "sign differs between seeds")
        summary.append(f"| {short(scene)} | {p} | " + ", ".join(f"{c * 100:+.1f} %" for c in changes)
                       + f" | {verdict} |")
    return lines, summary


# The latency breakdown of a ray, fifo against treeletPrefetch on seed 0
# (rays.latencyBreakdown / rays): where treelet prefetching's time goes.
BREAKDOWN = [("waiting for a ray slot (`inputQueue`)", ["inputQueue"]),
             ("`fetch` (L1 hit latency, the port's queue and transfer)", ["fetch"]),
             ("`l2` (bank queue and hit latency of a step's last line)", ["l2"]),
             ("`dram`", ["dram"]),
             ("box, triangle and transform units, with their queues",
              ["boxUnit", "boxUnitWait", "triangleUnit", "triangleUnitWait", "transformUnit", "transformUnitWait"]),
             ("the whole latency", None)]


def breakdown_table(policies):
    seed0 = [r for r in policies if r["workload"].endswith("&seed=0")]
    scenes = list(dict.fromkeys(r["workload"] for r in seed0))
    lines = ["| cycles per ray, fifo → treeletPrefetch | " + " | ".join(short(w.split("&")[0]) for w in scenes) + " |",
             "|---|" + "---:|" * len(scenes)]

    def per_ray(row, parts):
        rays = row["stats"]["frames"][0]["rtcore"]["rays"]
        b = rays["latencyBreakdown"]
        total = sum(b.values()) if parts is None else sum(b[k] for k in parts)
        return total / rays["latency"]["count"]

    for label, parts in BREAKDOWN:
        cells = []
        for w in scenes:
            by = {policy_of(r): r for r in seed0 if r["workload"] == w}
            cells.append(f"{per_ray(by['fifo'], parts):,.0f} → {per_ray(by['treeletPrefetch'], parts):,.0f}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return lines


def traffic_table(policies):
    """Seed 0: what fifo, treelet prefetching and ray reordering move through the memory path."""
    lines = ["| workload, seed 0 | policy | cycles | L1 hit rate | prefetched lines (share used) | port reads | "
             "L2 accesses | DRAM reads | mean ray latency |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for row in policies:
        policy = policy_of(row)
        if not row["workload"].endswith("&seed=0") or policy not in ("fifo", "treeletPrefetch",
                                                                       "rayOrder=directionOrigin"):
            continue
        r = row["stats"]["frames"][0]["rtcore"]
        prefetch = r["cache"].get("prefetch")
        prefetched = (f"{thousands(prefetch['lines'])} ({prefetch['accuracy']:.2f})" if prefetch else "—")
        lines.append(f"| {short(row['workload'].split('&')[0])} | {policy} | {thousands(row['metrics']['cycles'])} | "
                     f"{r['cache']['hitRate']:.3f} | {prefetched} | {r['memory']['readBytes'] / 1e6:.1f} MB | "
                     f"{thousands(r['l2']['accesses'])} | {r['dram']['readBytes'] / 1e6:.1f} MB | "
                     f"{thousands(round(r['rays']['latency']['mean']))} |")
    return lines


def service_order_table(rows_):
    """Cycles and the L2 banks' queueing under l2.serviceOrder made and arrival, fifo and treeletPrefetch."""
    lines = ["| workload | policy | cycles, order made | cycles, order of arrival | arrival vs made | "
             "vs fifo, made | vs fifo, arrival | L2 bank wait per access | accesses finding their bank busy | "
             "`l2` cycles per ray |",
             "|---|---|---:|---:|---:|---:|---:|---|---|---|"]
    by = {(r["workload"], r["overrides"]["scheduler.policy"], r["overrides"]["l2.serviceOrder"]): r for r in rows_}

    def l2(row):
        return row["stats"]["frames"][0]["rtcore"]["l2"]

    def per_ray_l2(row):
        rays = row["stats"]["frames"][0]["rtcore"]["rays"]
        return rays["latencyBreakdown"]["l2"] / rays["latency"]["count"]

    for workload in dict.fromkeys(r["workload"] for r in rows_):
        for policy in ("fifo", "treeletPrefetch"):
            made, arrival = by[(workload, policy, "made")], by[(workload, policy, "arrival")]
            cm, ca = made["metrics"]["cycles"], arrival["metrics"]["cycles"]
            fm = by[(workload, "fifo", "made")]["metrics"]["cycles"]
            fa = by[(workload, "fifo", "arrival")]["metrics"]["cycles"]
            vs_fifo = ("—", "—") if policy == "fifo" else (f"{(cm / fm - 1) * 100:+.1f} %", f"{(ca / fa - 1) * 100:+.1f} %")
            lm, la = l2(made), l2(arrival)
            lines.append(
                f"| {short(workload)} | {policy} | {thousands(cm)} | {thousands(ca)} | {(ca / cm - 1) * 100:+.1f} % | "
                f"{vs_fifo[0]} | {vs_fifo[1]} | "
                f"{lm['bankWaitCycles'] / lm['accesses']:.1f} → {la['bankWaitCycles'] / la['accesses']:.1f} | "
                f"{lm['bankConflicts'] / lm['accesses']:.2f} → {la['bankConflicts'] / la['accesses']:.2f} | "
                f"{per_ray_l2(made):,.0f} → {per_ray_l2(arrival):,.0f} |")
    return lines


def page_tables():
    """Each marked table of the page: name -> its lines."""
    with open(PAGE) as f:
        lines = f.read().split("\n")
    tables = {}
    for i, line in enumerate(lines):
        match = re.fullmatch(r"<!-- gpu-study: (\S+) -->", line)
        if match:
            end = i + 1
            while end < len(lines) and lines[end].strip():
                end += 1
            tables[match.group(1)] = lines[i + 1:end]
    return tables


def check(tables):
    """Exit status 1 with a diff when a table of the page differs from `tables`."""
    import difflib
    on_page = page_tables()
    differ = 0
    for name, table in tables.items():
        if name not in on_page:
            differ += 1
            print(f"gpu_study: {PAGE} has no marker '<!-- gpu-study: {name} -->'")
        elif on_page[name] != table:
            differ += 1
            print(f"gpu_study: table '{name}' of {PAGE} differs from the results "
                  f"(make gpu-study rewrites it):")
            print("\n".join(difflib.unified_diff(on_page[name], table, "page", "results", lineterm="")))
    extra = sorted(set(on_page) - set(tables))
    for name in extra:
        print(f"gpu_study: {PAGE} has a marker '{name}' that no table fills")
    if differ or extra:
        return 1
    print(f"gpu_study: {PAGE}: the {len(tables)} tables match the results")
    return 0


def rewrite(tables):
    with open(PAGE) as f:
        lines = f.read().split("\n")
    for name, table in tables.items():
        marker = f"<!-- gpu-study: {name} -->"
        if marker not in lines:
            sys.exit(f"gpu_study: no '{marker}' in {PAGE}")
        start = lines.index(marker) + 1
        end = start
        while end < len(lines) and lines[end].strip():
            end += 1
        lines[start:end] = table
    with open(PAGE, "w") as f:
        f.write("\n".join(lines))
    print(f"gpu_study: {PAGE}: {len(tables)} tables rewritten")


def main(argv):
    if not argv or argv[0].startswith("-"):
        sys.exit(__doc__)
    rtlab = argv[0]
    out = argv[argv.index("--out") + 1] if "--out" in argv else os.path.join(ROOT, "out", "gpu-study")
    if "--check" in argv and "--reuse" not in argv:
        import tempfile
        with tempfile.TemporaryDirectory(prefix="gpu-study-check-") as fresh:
            return study(rtlab, fresh, argv)
    return study(rtlab, out, argv)


def study(rtlab, out, argv):
    jobs = argv[argv.index("--jobs") + 1] if "--jobs" in argv else "2"
    results = {}
    for name in STUDIES:
        directory = os.path.join(out, name)
        if "--reuse" not in argv:
            run([rtlab, "sweep", os.path.join(ROOT, "docs", "studies", name + ".json"), "--out", directory,
                 "--jobs", jobs])
            if "--check" not in argv:
                run([rtlab, "report", directory])
        results[name] = rows(directory)
    policy, summary = policy_table(results["gpu-policies"])
    tables = {"utilization": utilization_table(results["gpu-scaling"]),
              "scaling": scaling_table(results["gpu-scaling"]),
              "memory": memory_table(results["gpu-memory"]),
              "policies": policy,
              "policy-summary": summary,
              "prefetch-breakdown": breakdown_table(results["gpu-policies"]),
              "traffic": traffic_table(results["gpu-policies"]),
              "service-order": service_order_table(results["gpu-service-order"])}
    if "--check" in argv:
        return check(tables)
    rewrite(tables)
    for name, plot in (("gpu-scaling", "cycles-vs-gpu.cores.png"),):
        source = os.path.join(out, name, "plots", plot)
        if os.path.exists(source):
            shutil.copyfile(source, os.path.join(ROOT, "docs", "studies", name + "-" + plot))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
