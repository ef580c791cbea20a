#!/usr/bin/env python3
"""Markdown table of a perf/rtcore_gpu_study CSV (docs/rtcore-model.md, "GPU study").
One row per workload x L1 x L2: fifo's cycles per seed, their change against
fifo with the smallest L1 and L2 per seed, whether a change of >= 10 % holds on
every seed, the largest change any other policy makes against fifo at the same
point (per seed), and the stats that say why (means over seeds).
Usage: rtcore_gpu_study_table.py grid.csv"""
import collections, csv, sys

rows = list(csv.DictReader(open(sys.argv[1])))
by = collections.defaultdict(dict)
for r in rows:
    by[(r["scene"], r["policy"], int(r["l1Bytes"]), int(r["l2Bytes"]))][r["seed"]] = r
scenes = list(dict.fromkeys(r["scene"] for r in rows))
seeds = sorted({r["seed"] for r in rows}, key=int)
policies = list(dict.fromkeys(r["policy"] for r in rows))
l1s = sorted({int(r["l1Bytes"]) for r in rows})
l2s = sorted({int(r["l2Bytes"]) for r in rows})
mean = lambda d, k: sum(float(d[s][k]) for s in seeds) / len(seeds)
kib = lambda b: f"{b // 1048576} MiB" if b >= 1048576 else f"{b // 1024} KiB"

print(f"| workload | L1 | L2 | fifo cycles (seeds {', '.join(seeds)}) | vs smallest L1+L2 | >= 10 % on every seed | other policies vs fifo (largest per seed) | L1 / L2 hit rate | DRAM util. | latency share: L2+DRAM / input queue |")
print("|---|---|---|---|---|---|---|---|---|---|")
for sc in scenes:
    base = by[(sc, "fifo", l1s[0], l2s[0])]
    for l1 in l1s:
        for l2 in l2s:
            d = by[(sc, "fifo", l1, l2)]
            if any(s not in d or s not in base for s in seeds):
                continue
            rel = [int(d[s]["cycles"]) / int(base[s]["cycles"]) - 1 for s in seeds]
            holds = "—" if (l1, l2) == (l1s[0], l2s[0]) else (
                "yes, faster" if all(x <= -0.10 for x in rel) else "yes, slower" if all(x >= 0.10 for x in rel) else "no")
            spread = []
            for s in seeds:
                others = [int(by[(sc, p, l1, l2)][s]["cycles"]) / int(d[s]["cycles"]) - 1
                          for p in policies if p != "fifo" and s in by[(sc, p, l1, l2)]]
                spread.append(max(others, key=abs) if others else 0.0)
            print(f"| {sc.replace('builtin:', '')} | {kib(l1)} | {kib(l2)} | "
                  f"{' / '.join(format(int(d[s]['cycles']), ',') for s in seeds)} | "
                  f"{' / '.join(f'{x * 100:+.0f} %' for x in rel)} | {holds} | "
                  f"{' / '.join(f'{x * 100:+.1f} %' for x in spread)} | "
                  f"{mean(d, 'l1HitRate'):.2f} / {mean(d, 'l2HitRate'):.2f} | {mean(d, 'dramUtilization'):.2f} | "
                  f"{mean(d, 'shareL2') + mean(d, 'shareDram'):.2f} / {mean(d, 'shareInputQueue'):.2f} |")
