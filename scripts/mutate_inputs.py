#!/usr/bin/env python3
"""Random truncations and bit flips of real input files through the rtlab CLI.

Each case takes a seed file, either cuts it at a random length (30%) or changes
1, 2, 4 or 16 random bytes (a bit flip 70% of the time, else a random byte),
writes it beside nothing else (textures and .mtl files are not copied), and
runs `rtlab info --scene CASE` with a time limit. A case fails when rtlab
crashes (exit not 0 or 2), hangs past the limit, or exits 2 with other than one
line naming the problem; failing inputs are kept in OUT/ for
tests/regression_inputs/. Deterministic for a seed.

usage: scripts/mutate_inputs.py [--rtlab BIN] [--format obj|ply|fbx|all] [--cases N] [--seed S]
                                [--timeout SECONDS] [--out DIR]
"""
import argparse, glob, os, random, shutil, subprocess, sys, tempfile, time

MODELS = "/usr/share/assimp/models"
SEEDS = {
    "obj": sorted(glob.glob(f"{MODELS}/OBJ/*.obj")),
    "ply": sorted(f for f in glob.glob(f"{MODELS}/PLY/*.ply") if not f.endswith("pond.0.ply")),  # 2 MB: slow cases
    "fbx": sorted(glob.glob(f"{MODELS}/FBX/*.fbx") + glob.glob(f"{MODELS}/FBX/*.FBX")),
}

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--rtlab", default="build/release/apps/rtlab")
ap.add_argument("--format", default="all", choices=["all", *SEEDS])
ap.add_argument("--cases", type=int, default=1000, help="cases per format")
ap.add_argument("--seed", type=int, default=1)
ap.add_argument("--timeout", type=float, default=10.0)
ap.add_argument("--out", default="out/mutate")
a = ap.parse_args()
if not os.path.exists(MODELS):
    sys.exit("mutate_inputs: assimp-testmodels missing (scripts/install-deps.sh installs it)")
os.makedirs(a.out, exist_ok=True)
work = tempfile.mkdtemp(prefix="rtlab_mutate_")
failures = 0
for fmt in SEEDS if a.format == "all" else [a.format]:
    rng = random.Random(f"{a.seed}/{fmt}")
    counts = {"loaded": 0, "exit2": 0, "failed": 0}
    started = time.time()
    for i in range(a.cases):
        seed_file = rng.choice(SEEDS[fmt])
        data = bytearray(open(seed_file, "rb").read())
        if rng.random() < 0.3 and len(data) > 1:
            data = data[: rng.randrange(len(data))]
        else:
            for _ in range(rng.choice([1, 1, 2, 4, 16])):
                if data:
                    p = rng.randrange(len(data))
                    data[p] = data[p] ^ (1 << rng.randrange(8)) if rng.random() < 0.7 else rng.randrange(256)
        case = os.path.join(work, "case" + os.path.splitext(seed_file)[1])
        open(case, "wb").write(data)
        try:
            r = subprocess.run([a.rtlab, "info", "--scene", case], capture_output=True, text=True, errors="replace",
                               timeout=a.timeout)
            err = r.stderr.strip()
            ok = r.returncode == 0 or (r.returncode == 2 and err.count("\n") == 0 and err.startswith("rtlab:"))
            why = f"exit {r.returncode}" + ("" if r.returncode in (0, 2) else " (crash)") + f": {err[-300:]}"
        except subprocess.TimeoutExpired:
            ok, why = False, f"no answer within {a.timeout:.0f} s"
        if ok:
            counts["loaded" if r.returncode == 0 else "exit2"] += 1
            continue
        counts["failed"] += 1
        failures += 1
        kept = os.path.join(a.out, f"{fmt}_{a.seed}_{i}{os.path.splitext(seed_file)[1]}")
        shutil.copy(case, kept)
        print(f"mutate_inputs: {fmt} case {i} from {os.path.relpath(seed_file, MODELS)}: {why}; kept as {kept}",
              flush=True)
    print(f"mutate_inputs: {fmt}: {a.cases} cases in {time.time() - started:.0f} s: {counts['loaded']} loaded, "
          f"{counts['exit2']} exit 2 with one line, {counts['failed']} failed", flush=True)
shutil.rmtree(work, ignore_errors=True)
sys.exit(1 if failures else 0)
