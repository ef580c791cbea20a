#!/usr/bin/env python3
"""Behaviour-unchanged check for refactors: renders a fixed set of commands
with an rtlab binary into DIR, keeping every output file, with the run-to-run
varying parts of stats.json / converge.json (timings, Embree's own memory,
paths) removed. Two such directories from two builds must be identical:

    scripts/golden_outputs.py BIN_BEFORE /tmp/before
    scripts/golden_outputs.py BIN_AFTER  /tmp/after
    scripts/golden_outputs.py --compare /tmp/before /tmp/after

Covers render (showcase every effect incl. DDGI and the path tracer, 2
frames; forest and terrain small), both back ends, ray recording and replay,
plan --json and converge. Small sizes: about a minute on 2 cores.
"""
import filecmp
import json
import os
import shutil
import subprocess
import sys

SIZE = ["--width", "96", "--height", "54"]

# (name, arguments after the binary); "{out}" is the case's directory.
CASES = [
    ("showcase-embree", ["render", "--scene", "builtin:showcase", "--frames", "2", *SIZE,
                         "--record-rays", "{out}/rays", "--out", "{out}"]),
    ("showcase-rtcore", ["render", "--scene", "builtin:showcase", "--frames", "2", *SIZE,
                         "--backend", "rtcore", "--record-rays", "{out}/rays", "--out", "{out}"]),
    ("showcase-ddgi", ["render", "--scene", "builtin:showcase", "--frames", "2", *SIZE, "--gi", "ddgi",
                       "--out", "{out}"]),
    ("showcase-pathtrace-rtcore", ["render", "--scene", "builtin:showcase", "--frames", "2", *SIZE,
                                   "--effects", "pathtrace", "--max-depth", "3", "--backend", "rtcore",
                                   "--spp", "2", "--seed", "7", "--out", "{out}"]),
    ("showcase-nondefault", ["render", "--scene", "builtin:showcase", "--frames", "1", *SIZE,
                             "--max-translucency-depth", "3", "--ao-radius", "0.5", "--ao-contact-samples", "2",
                             "--reflection-roughness", "0.5", "--denoise", "none", "--out", "{out}"]),
    ("forest-embree", ["render", "--scene", "builtin:forest?instances=50", "--frames", "2", *SIZE,
                       "--record-rays", "{out}/rays", "--out", "{out}"]),
    ("forest-rtcore", ["render", "--scene", "builtin:forest?instances=50", "--frames", "2", *SIZE,
                       "--backend", "rtcore", "--rtcore-set", "gpu.cores=2", "--out", "{out}"]),
    ("terrain-embree", ["render", "--scene", "builtin:terrain?triangles=5000", "--frames", "2", *SIZE,
                        "--effects", "shadows,ao,pathtrace", "--out", "{out}"]),
    ("terrain-rtcore", ["render", "--scene", "builtin:terrain?triangles=5000", "--frames", "2", *SIZE,
                        "--backend", "rtcore", "--record-rays", "{out}/rays", "--out", "{out}"]),
    ("replay-terrain-rtcore", ["replay", "--scene", "builtin:terrain?triangles=5000",
                               "--rays", "{root}/terrain-rtcore/rays", "--backend", "rtcore", "--out", "{out}"]),
    ("showcase-opaque-rtcore", ["render", "--scene", "builtin:showcase", "--frames", "2", *SIZE, "--backend",
                                "rtcore", "--effects", "shadows,reflections,ao,gi,translucency,volumes",
                                "--record-rays", "{out}/rays", "--out", "{out}"]),
    ("replay-showcase-rtcore", ["replay", "--scene", "builtin:showcase", "--backend", "rtcore",
                                "--rays", "{root}/showcase-opaque-rtcore/rays", "--out", "{out}"]),
    ("replay-forest-embree", ["replay", "--scene", "builtin:forest?instances=50",
                              "--rays", "{root}/forest-embree/rays", "--out", "{out}"]),
    ("converge-ao", ["converge", "--scene", "builtin:showcase", "--effect", "ao", *SIZE, "--reference-spp", "8",
                     "--max-spp", "2", "--denoise-max-spp", "1", "--frames", "2", "--cache", "{out}/cache",
                     "--out", "{out}"]),
    ("converge-translucency", ["converge", "--scene", "builtin:showcase", "--effect", "translucency", *SIZE,
                               "--reference-spp", "4", "--max-spp", "1", "--denoise-max-spp", "1", "--frames", "1",
                               "--cache", "{out}/cache", "--out", "{out}"]),
]
PLANS = [("plan-showcase", ["plan", "--scene", "builtin:showcase", "--json"]),
         ("plan-showcase-text", ["plan", "--scene", "builtin:showcase", "--effects", "shadows,gi", "--gi", "ddgi"])]

# Keys whose values are wall time or Embree's own (thread-dependent) memory.
VARYING = {"timing", "measured", "ms", "rawMsAtEqualError", "speedup", "speedupFrames", "extrapolated",
           "extrapolatedFrames", "rawFramesMsAtEqualError", "equalErrorSpeedup", "equalErrorSpeedupFrames",
           "threadsUsed", "cached"}


def scrub_json(path, root):
    with open(path) as f:
        data = json.load(f)

    def walk(v):
        if isinstance(v, dict):
            return {k: walk(x) for k, x in v.items() if k not in VARYING}
        if isinstance(v, list):
            return [walk(x) for x in v]
        if isinstance(v, str):
            return v.replace(root, "ROOT")
        return v

    with open(path, "w") as f:
        json.dump(walk(data), f, indent=1, sort_keys=True)


def run(binary, root):
    shutil.rmtree(root, ignore_errors=True)
    os.makedirs(root)
    for name, args in CASES:
        out = os.path.join(root, name)
        argv = [binary] + [a.format(out=out, root=root) for a in args]
        r = subprocess.run(argv, capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit(f"{name}: exit {r.returncode}: {r.stderr.strip()}")
        if name.startswith("converge"):
            with open(os.path.join(out, "table.txt"), "w") as f:
                # The table without its ms and speed-up columns (wall time).
                for line in r.stdout.splitlines():
                    if line.startswith("wrote "):
                        continue
                    f.write(" ".join(w for w in line.split()[:3]) + "\n")
            shutil.rmtree(os.path.join(out, "cache"))
            os.remove(os.path.join(out, "converge.png"))  # axes are wall milliseconds
            os.remove(os.path.join(out, "converge.csv"))  # ms columns; the JSON keeps the rest
        for dirpath, _, files in os.walk(out):
            for f in files:
                if f.endswith(".json"):
                    scrub_json(os.path.join(dirpath, f), root)
        print(f"golden: {name}", file=sys.stderr)
    for name, args in PLANS:
        r = subprocess.run([binary] + args, capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit(f"{name}: exit {r.returncode}: {r.stderr.strip()}")
        with open(os.path.join(root, name + ".txt"), "w") as f:
            f.write(r.stdout)


def compare(a, b):
    differ = []

    def walk(cmp, prefix):
        differ.extend(os.path.join(prefix, f) for f in cmp.diff_files + cmp.left_only + cmp.right_only)
        for name, sub in cmp.subdirs.items():
            walk(sub, os.path.join(prefix, name))

    walk(filecmp.dircmp(a, b, ignore=[]), "")
    # dircmp compares shallowly (size + mtime); confirm byte by byte.
    real = [p for p in differ if not (os.path.isfile(os.path.join(a, p)) and os.path.isfile(os.path.join(b, p))
                                      and filecmp.cmp(os.path.join(a, p), os.path.join(b, p), shallow=False))]
    files = sum(len(f) for _, _, f in os.walk(a))
    if real:
        print(f"golden: {len(real)} of {files} files differ:")
        for p in real:
            print("  " + p)
        return 1
    print(f"golden: all {files} files identical")
    return 0


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--compare":
        sys.exit(compare(sys.argv[2], sys.argv[3]))
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    run(sys.argv[1], sys.argv[2])
