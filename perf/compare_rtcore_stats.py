#!/usr/bin/env python3
"""Side-by-side figures of two or more `rtlab render --backend rtcore` runs.

Usage: perf/compare_rtcore_stats.py A/stats.json B/stats.json [...] [--frame N]

Prints, per run, the configuration values that differ between the runs and
the frame's headline figures from the stats tree (docs/rtcore-model.md,
"Statistics"); the last column is each run's cycles relative to the first.
"""
import json, sys


def flatten(tree, prefix=""):
    out = {}
    for k, v in tree.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out


def main(argv):
    frame = 0
    paths = []
    i = 0
    while i < len(argv):
        if argv[i] == "--frame":
            frame = int(argv[i + 1])
            i += 2
            continue
        paths.append(argv[i])
        i += 1
    if len(paths) < 2:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    runs = []
    for p in paths:
        try:
            with open(p) as f:
                s = json.load(f)
            runs.append((p, flatten(s["rtcore"]["config"]), s["frames"][frame]["rtcore"]))
        except (OSError, ValueError, KeyError, IndexError) as e:
            print(f"{p}: not the stats.json of an rtcore render with frame {frame} ({e})", file=sys.stderr)
            return 2
    keys = sorted(set().union(*(c.keys() for _, c, _ in runs)))
    differing = [k for k in keys if len({json.dumps(c.get(k)) for _, c, _ in runs}) > 1]
    figures = [
        ("cycles", lambda r: r["frame"]["cycles"]),
        ("rays", lambda r: r["frame"]["rays"]),
        ("rays/cycle", lambda r: r["frame"]["raysPerCycle"]),
        ("mean latency", lambda r: r["rays"]["latency"]["mean"]),
        ("node visits/ray", lambda r: r["rays"]["nodeVisits"]["mean"]),
        ("triangle tests/ray", lambda r: r["rays"]["triangleTests"]["mean"]),
        ("cache hit rate", lambda r: r["cache"]["hitRate"]),
        ("memory bytes read", lambda r: r["memory"]["readBytes"]),
        ("box unit utilization", lambda r: r["traversalUnits"]["utilization"]),
        ("triangle unit utilization", lambda r: r["triangleUnits"]["utilization"]),
        ("scheduler utilization", lambda r: r["scheduler"]["utilization"]),
        ("SIMD efficiency", lambda r: r["simd"]["efficiency"]),
    ]
    width = max(12, *(len(p) for p in paths))
    print(f"frame {frame}")
    print(f"{'':28}" + "".join(f"{p:>{width + 2}}" for p in paths))
    for k in differing:
        print(f"{'config ' + k:28}" + "".join(f"{str(c.get(k)):>{width + 2}}" for _, c, _ in runs))
    for name, get in figures:
        vals = []
        for _, _, r in runs:
            try:
                v = get(r)
                vals.append(f"{v:.4g}" if isinstance(v, float) else str(v))
            except (KeyError, TypeError):
                vals.append("-")
        print(f"{name:28}" + "".join(f"{v:>{width + 2}}" for v in vals))
    base = runs[0][2]["frame"]["cycles"]
    print(f"{'cycles / first run':28}" + "".join(f"{r['frame']['cycles'] / base:>{width + 2}.3f}" for _, _, r in runs))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
