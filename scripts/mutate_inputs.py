#!/usr/bin/env python3
"""Random truncations and bit flips of real input files through the rtlab CLI.

Per format (the fuzz targets' formats, docs/reliability.md), each case takes a
seed file of the format (out/fuzz/seeds/FORMAT, as `scripts/fuzz.py
--seeds-only` puts them together), either cuts it at a random length (30%) or
changes 1, 2, 4 or 16 random bytes (a bit flip 70% of the time, else a random
byte), and runs the rtlab command that reads that format with a time limit:

  gltf, glb, scene_json, obj, ply, fbx   render --scene CASE at 32x18, --denoise none
                                         (a scene_json case beside a one-triangle model.gltf)
  vdb                                    render of a scene .json naming CASE
  mtl                                    render of a fixed OBJ whose mtllib is CASE
  ray_trace                              replay --scene builtin:cornell --rays CASE (embree, rtcore alternately)
  study                                  sweep CASE (its workloads made 8x8 renders of the Cornell box)
  rtcore_config                          render --backend rtcore --rtcore-config CASE
  exr                                    compare CASE CASE

A case fails when rtlab crashes (exit not 0, 1 for a replay whose hits
differ, or 2), hangs past the limit, or exits 2 with other than one line;
failing inputs are kept in OUT/ for tests/regression_inputs/. Deterministic
for a seed. Two cases run at a time (--jobs).

usage: scripts/mutate_inputs.py [--rtlab BIN] [--format F|all] [--cases N] [--seed S]
                                [--timeout SECONDS] [--seeds out/fuzz/seeds] [--out DIR] [--jobs N]
"""
import argparse, concurrent.futures, glob, json, os, random, shutil, subprocess, sys, tempfile, time

FORMATS = ["gltf", "glb", "scene_json", "vdb", "obj", "mtl", "ply", "fbx", "ray_trace", "study", "rtcore_config", "exr"]
EXTENSION = {"gltf": ".gltf", "glb": ".glb", "scene_json": ".json", "vdb": ".vdb", "obj": ".obj", "mtl": ".mtl",
             "ply": ".ply", "fbx": ".fbx", "ray_trace": ".rays", "study": ".json", "rtcore_config": ".json",
             "exr": ".exr"}
QUAD_OBJ = ("mtllib case.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
            "usemtl material\nf 1/1 2/2 3/3\nusemtl other\nf 1/1 3/3 4/4\n")
# The model beside every scene_json case (the seed gltf_model.json names it; the
# fuzz target and the regression test put the same file beside theirs): one triangle.
MODEL_GLTF = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "fuzz", "scene_json_model.gltf")
VDB_SCENE = ('{"gltf": [], "volumes": [{"file": "case.vdb", "densityScale": 0.5}], '
             '"camera": {"position": [0, 1, 6], "lookAt": [0, 0, 0], "yfov": 0.8}}')


def small_study(data):
    """A study seed with its workloads made the Cornell box at 8x8 (mutations of it stay quick to run)."""
    try:
        study = json.loads(data)
        study["workloads"] = ["builtin:cornell"]
        study.setdefault("render", {}).update({"width": 8, "height": 8, "frames": 1, "effects": "gbuffer"})
        return json.dumps(study, indent=1).encode()
    except (ValueError, AttributeError):
        return data


def commands(rtlab, fmt, case, work, i):
    out = ["--out", os.path.join(work, "out")]
    render = [rtlab, "render", "--width", "32", "--height", "18", "--denoise", "none", *out, "--scene"]
    if fmt == "vdb":
        open(os.path.join(work, "scene.json"), "w").write(VDB_SCENE)
        return render + [os.path.join(work, "scene.json")]
    if fmt == "scene_json":
        shutil.copy(MODEL_GLTF, os.path.join(work, "model.gltf"))
    if fmt == "mtl":
        open(os.path.join(work, "case.obj"), "w").write(QUAD_OBJ)
        return render + [os.path.join(work, "case.obj")]
    if fmt == "ray_trace":
        return [rtlab, "replay", "--scene", "builtin:cornell", "--backend", ("embree", "rtcore")[i % 2], "--rays",
                case, *out]
    if fmt == "study":
        return [rtlab, "sweep", case, *out]
    if fmt == "rtcore_config":
        return [rtlab, "render", "--scene", "builtin:cornell", "--backend", "rtcore", "--effects", "gbuffer",
                "--width", "8", "--height", "8", "--denoise", "none", "--rtcore-config", case, *out]
    if fmt == "exr":
        return [rtlab, "compare", case, case]
    return render + [case]


def mutate(rng, data):
    if rng.random() < 0.3 and len(data) > 1:
        return data[: rng.randrange(len(data))]
    data = bytearray(data)
    for _ in range(rng.choice([1, 1, 2, 4, 16])):
        if data:
            p = rng.randrange(len(data))
            data[p] = data[p] ^ (1 << rng.randrange(8)) if rng.random() < 0.7 else rng.randrange(256)
    return bytes(data)


def run_case(a, fmt, i, seed_name, data, root):
    work = os.path.join(root, f"w{i % (4 * a.jobs)}")
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    case = os.path.join(work, "case" + EXTENSION[fmt])
    open(case, "wb").write(data)
    cmd = commands(a.rtlab, fmt, case, work, i)
    try:
        r = subprocess.run(cmd, capture_output=True, timeout=a.timeout)
        err = r.stderr.decode("utf-8", "replace").strip()
        one_line = err.count("\n") == 0 and err.startswith("rtlab:")
        ok = (r.returncode == 0 or (r.returncode == 2 and one_line) or
              (fmt == "ray_trace" and r.returncode == 1 and one_line and "differ from the recording" in err))
        why = f"exit {r.returncode}" + ("" if r.returncode in (0, 1, 2) else " (crash)") + f": {err[-300:]}"
        outcome = "loaded" if r.returncode == 0 else ("differ" if r.returncode == 1 else "exit2")
    except subprocess.TimeoutExpired:
        ok, why, outcome = False, f"no answer within {a.timeout:.0f} s", "hang"
    if ok:
        return outcome, None
    kept = os.path.join(a.out, f"{fmt}_{a.seed}_{i}{EXTENSION[fmt]}")
    shutil.copy(case, kept)
    beside = " (reproduce with fuzz/scene_json_model.gltf beside it as model.gltf)" if fmt == "scene_json" else ""
    return "failed", f"mutate_inputs: {fmt} case {i} from {seed_name}: {why}; kept as {kept}{beside} ({' '.join(cmd)})"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rtlab", default="build/release/apps/rtlab")
    ap.add_argument("--format", default="all", choices=["all", *FORMATS])
    ap.add_argument("--cases", type=int, default=1000, help="cases per format")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=10.0)
    ap.add_argument("--seeds", default="out/fuzz/seeds", help="seed files per format (scripts/fuzz.py --seeds-only)")
    ap.add_argument("--out", default="out/mutate")
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    a.rtlab = os.path.abspath(a.rtlab)
    os.makedirs(a.out, exist_ok=True)
    root = tempfile.mkdtemp(prefix="rtlab_mutate_")
    failures = 0
    for fmt in FORMATS if a.format == "all" else [a.format]:
        seeds = sorted(glob.glob(os.path.join(a.seeds, fmt, "*")))
        if not seeds:
            sys.exit(f"mutate_inputs: no seeds in {a.seeds}/{fmt} (run scripts/fuzz.py --seeds-only first)")
        contents = {p: open(p, "rb").read() for p in seeds}
        if fmt == "study":
            contents = {p: small_study(d) for p, d in contents.items()}
        rng = random.Random(f"{a.seed}/{fmt}")
        cases = []
        for i in range(a.cases):
            seed_file = rng.choice(seeds)
            cases.append((i, os.path.basename(seed_file), mutate(rng, contents[seed_file])))
        counts = {"loaded": 0, "exit2": 0, "differ": 0, "failed": 0}
        started = time.time()
        with concurrent.futures.ThreadPoolExecutor(a.jobs) as pool:
            for outcome, message in pool.map(lambda c: run_case(a, fmt, *c, root), cases):
                counts[outcome if outcome in counts else "failed"] += 1
                if message:
                    failures += 1
                    print(message, flush=True)
        print(f"mutate_inputs: {fmt}: {a.cases} cases from {len(seeds)} seeds in {time.time() - started:.0f} s: "
              f"{counts['loaded']} loaded, {counts['exit2']} exit 2 with one line"
              + (f", {counts['differ']} replays whose hits differ (exit 1)" if fmt == "ray_trace" else "")
              + f", {counts['failed']} failed", flush=True)
    shutil.rmtree(root, ignore_errors=True)
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
