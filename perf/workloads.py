#!/usr/bin/env python3
"""The workload table (`make workloads`): for each suite workload and ray
type, what the RT-core model sees. Per workload, one frame is rendered on
Embree with shadows, AO and a 2-bounce path tracer, its rays recorded
(--record-rays); then each ray type is replayed alone on the model
(rtlab replay --ray-types T) with a 32 KiB and a 1 MiB node cache. Writes
OUT/workloads.json and the markdown table DOC (docs/workloads.md).

usage: perf/workloads.py RTLAB [OUT_DIR] [DOC] [--table-only]
(--table-only: write DOC again from OUT/workloads.json without running anything)"""
import datetime, json, pathlib, re, subprocess, sys, time

table_only = "--table-only" in sys.argv
argv = [a for a in sys.argv if a != "--table-only"]
rtlab = argv[1] if len(argv) > 1 else "build/release/apps/rtlab"
out = pathlib.Path(argv[2] if len(argv) > 2 else "out/workloads")
doc = pathlib.Path(argv[3] if len(argv) > 3 else "docs/workloads.md")

WIDTH, HEIGHT, DEPTH = 160, 90, 2
ENGINE = "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb"
SPIDER = "/usr/share/assimp/models/OBJ/spider.obj"  # OBJ + MTL + JPEG textures, through the OBJ importer
WORKLOADS = [
    ("showcase", "builtin:showcase"),
    ("cornell", "builtin:cornell"),
    ("2CylinderEngine", ENGINE),
    ("terrain 1M", "builtin:terrain?triangles=1000000"),
    ("forest 10k", "builtin:forest?instances=10000"),
    ("hairball 1M", "builtin:hairball?triangles=1000000"),
    ("slivers 1M", "builtin:slivers?triangles=1000000"),
    ("spider (OBJ)", SPIDER),
]
RAY_TYPES = [("primary", "primary"), ("shadow", "shadow"), ("ao", "AO"), ("pathBounce", "pathtrace bounce")]
CACHES = [(32768, "32 KiB"), (1048576, "1 MiB")]


# The scenes RT-hardware and traversal papers report on: where each is
# published, its licence as the publisher states it, and the commands that run
# it. Not downloaded by rtlab (no network in CI); a user fetches and unpacks them.
STANDARD_SCENES = """## The standard scenes of RT-hardware papers

rtlab reads the formats these scenes ship in (`docs/scene-format.md`: OBJ + MTL, FBX, PLY, glTF). They
are not part of this repository or its tests (sizes and licences); download and unpack one, then run
it with the commands below. Licences are as the publisher's page states them: check the page before
you redistribute renders or the files.

| scene | where it is published | format | licence (as published) | camera |
|---|---|---|---|---|
| Crytek Sponza (262k triangles, alpha-masked foliage and chains) | Morgan McGuire's Computer Graphics Archive, https://casual-effects.com/data/ (`sponza.zip`) | OBJ + MTL + textures | CC BY 3.0 (Frank Meinl, Crytek) | `--camera interior` |
| San Miguel (10M triangles, alpha-masked leaves) | the same archive (`San_Miguel.zip`) | OBJ + MTL + textures | CC BY 3.0 (Guillermo M. Leal Llaguno) | `--camera interior` or the file's bounds |
| Hairball (2.9M triangles of curly strands) | the same archive (`hairball.zip`; Samuli Laine, NVIDIA Research) | OBJ | CC BY 3.0 | default (`builtin:hairball` is its look-alike) |
| Conference room (331k triangles) | the same archive (`conference.zip`; Anat Grynberg and Greg Ward) | OBJ + MTL | as the archive's page states | `--camera interior` |
| Fairy Forest (174k triangles, animated) | Utah 3D Animation Repository, https://www.sci.utah.edu/~wald/animrep/ | OBJ per frame | free for research, credit the repository | default |
| Amazon Lumberyard Bistro (exterior 2.8M, interior 1M triangles) | NVIDIA ORCA, https://developer.nvidia.com/orca/amazon-lumberyard-bistro | FBX | CC BY 4.0 (Amazon Lumberyard) | `--camera interior` or a `--camera` of your own |
| Stanford Bunny, Dragon, Armadillo, Happy Buddha | Stanford 3D Scanning Repository, https://graphics.stanford.edu/data/3Dscanrep/ | PLY | research use; credit the Stanford Computer Graphics Laboratory; no commercial use without permission | default |

Sponza, with one command each (the scene file as unpacked; any scene above works the same way):

```sh
rtlab render --scene sponza/sponza.obj --camera interior --out out/sponza
rtlab render --scene sponza/sponza.obj --camera interior --effects shadows,ao,pathtrace --max-depth 2 --width 160 --height 90 --denoise none --record-rays out/sponza/rays --out out/sponza/recorded
rtlab replay --scene sponza/sponza.obj --rays out/sponza/rays --backend rtcore --ray-types primary --out out/sponza/primary
echo '{"workloads": [{"scene": "sponza/sponza.obj", "camera": "interior"}], "render": {"width": 128, "height": 72}, "grid": {"cache.sizeBytes": [16384, 65536]}}' > sponza-study.json
rtlab sweep sponza-study.json --out out/sponza-study && rtlab report out/sponza-study
```

- A file whose parts are not found (a missing .mtl or texture) still renders, with a warning in
  stats.json `load` and a default material (`docs/scene-format.md`).
- `rtlab info --scene FILE` prints the triangle counts and the bounds, from which a `--camera` of your
  own can be chosen (`--camera ex,ey,ez,tx,ty,tz[,ux,uy,uz[,fovYDegrees]]`).
- `rtlab export --scene 'builtin:terrain?triangles=300000' --out terrain.obj` writes the builtin
  workloads the other way, for Arches, pbrt or Blender.
""".splitlines()


def run(args):
    started = time.time()
    r = subprocess.run([rtlab] + args, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"workloads: rtlab {' '.join(args)} failed ({r.returncode}):\n{r.stderr}")
    return r.stdout, time.time() - started


def slug(name):
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")


rows, commands = [], []
if table_only:
    saved = json.loads((out / "workloads.json").read_text())
    rows, commands = saved["rows"], saved["commands"]
for name, source in [] if table_only else WORKLOADS:
    if source.startswith("/") and not pathlib.Path(source).exists():
        print(f"workloads: {source} missing (Debian's assimp-testmodels); skipped", file=sys.stderr)
        continue
    w = out / slug(name)
    info, _ = run(["info", "--scene", source])
    m = re.search(r"triangles: (\d+) unique, (\d+) instanced", info)
    unique, instanced = (int(m.group(1)), int(m.group(2))) if m else (None, None)
    render = ["render", "--scene", source, "--effects", "shadows,ao,pathtrace", "--max-depth", str(DEPTH),
              "--width", str(WIDTH), "--height", str(HEIGHT), "--denoise", "none",
              "--record-rays", str(w / "rays"), "--out", str(w / "render")]
    _, seconds = run(render)
    commands.append("rtlab " + " ".join(f"'{a}'" if "?" in a else a for a in render))
    print(f"workloads: {name}: rendered and recorded in {seconds:.1f} s", file=sys.stderr)
    frame = json.loads((w / "render" / "stats.json").read_text())["frames"][0]
    for ray_type, label in RAY_TYPES:
        if frame["rays"].get(ray_type, {}).get("traced", 0) == 0:
            continue
        row = {"workload": name, "source": source, "rayType": label, "uniqueTriangles": unique,
               "instancedTriangles": instanced, "rays": frame["rays"][ray_type]["traced"]}
        for size, size_label in CACHES:
            replay = ["replay", "--scene", source, "--rays", str(w / "rays"), "--backend", "rtcore",
                      "--ray-types", ray_type, "--rtcore-set", f"cache.sizeBytes={size}",
                      "--out", str(w / f"{ray_type}-{size}")]
            _, seconds = run(replay)
            if ray_type == "primary" and size == CACHES[0][0]:
                commands.append("rtlab " + " ".join(f"'{a}'" if "?" in a else a for a in replay))
            f = json.loads((w / f"{ray_type}-{size}" / "stats.json").read_text())["frames"][0]
            r = f["rtcore"]
            row["bvhBytes"] = f["rtcoreModelBytes"]
            row["nodeVisitsPerRay"] = r["rays"]["nodeVisits"]["mean"]
            row["leafVisitsPerRay"] = r["rays"]["leafVisits"]["mean"]
            row[f"cacheHitRate{size_label.replace(' ', '')}"] = r["cache"]["hitRate"]
            row[f"raysPerCycle{size_label.replace(' ', '')}"] = r["frame"]["raysPerCycle"]
            row["differingHits"] = row.get("differingHits", 0) + f["differingHits"]
            print(f"workloads: {name} {label} {size_label}: {seconds:.1f} s", file=sys.stderr)
        rows.append(row)

out.mkdir(parents=True, exist_ok=True)
(out / "workloads.json").write_text(json.dumps({"rows": rows, "commands": commands}, indent=2) + "\n")


def num(v, spec=","):
    return format(v, spec) if v is not None else "-"


memory_bound = [r for r in rows if r["cacheHitRate32KiB"] < 0.8]
lines = [
    "# Workloads",
    "",
    "What the RT-core model sees on the suite's workloads, per ray type. Written by `make workloads`",
    f"(`perf/workloads.py`) on {datetime.date.today().isoformat()}, default model configuration",
    "(`docs/rtcore-model.md`) except the node-cache size. All figures are deterministic; only the",
    "run time is not.",
    "",
    "How: each workload renders one frame at "
    f"{WIDTH}x{HEIGHT} on Embree with shadows, AO and a {DEPTH}-bounce path tracer",
    "(`--effects shadows,ao,pathtrace`), recording its rays (`--record-rays`,",
    "`docs/ray-trace-format.md`). Each ray type is then replayed alone on the model",
    "(`rtlab replay --ray-types T`), once with a 32 KiB and once with a 1 MiB node cache, so",
    "the figures of one ray type do not mix with another's. *Node / leaf visits* are internal",
    "and leaf nodes visited per ray, both BVH levels. *Hit rate* is the node cache's hit rate",
    "over node fetches. *Rays / cycle* is the model's throughput on that ray type alone. *BVH",
    "bytes* is the model's memory layout of every BLAS and the TLAS (`rtcoreModelBytes`).",
    "At this resolution a frame's rays touch a small part of the large BVHs once or twice, so",
    "compulsory misses bound the 1 MiB hit rates; more rays (a larger image, more frames) raise them.",
    "",
    "| workload | triangles (unique / instanced) | BVH bytes | ray type | rays | node visits / ray "
    "| leaf visits / ray | hit rate 32 KiB | hit rate 1 MiB | rays / cycle 32 KiB | rays / cycle 1 MiB |",
    "|---|---|---|---|---|---|---|---|---|---|---|",
]
for r in rows:
    lines.append(
        f"| {r['workload']} | {num(r['uniqueTriangles'])} / {num(r['instancedTriangles'])} | {num(r['bvhBytes'])} "
        f"| {r['rayType']} | {num(r['rays'])} | {r['nodeVisitsPerRay']:.1f} | {r['leafVisitsPerRay']:.1f} "
        f"| {r['cacheHitRate32KiB']:.3f} | {r['cacheHitRate1MiB']:.3f} | {r['raysPerCycle32KiB']:.3g} "
        f"| {r['raysPerCycle1MiB']:.3g} |")
lines += [
    "",
    "Workloads that miss the 32 KiB cache on more than 20% of node fetches (memory-bound: the ones a",
    "memory-system study needs): " + (", ".join(sorted({f"{r['workload']} ({r['rayType']})" for r in memory_bound}))
                                     if memory_bound else "none") + ".",
    "",
    f"Replayed hits that differ from the recorded (Embree) ones: {sum(r['differingHits'] for r in rows)}.",
    "",
    "The commands, per workload (the rest of the replays differ in `--ray-types` and `cache.sizeBytes`):",
    "",
    "```sh",
    *commands,
    "```",
    "",
    *STANDARD_SCENES,
]
doc.write_text("\n".join(lines))
print(f"workloads: {len(rows)} rows, {out / 'workloads.json'} and {doc}", file=sys.stderr)
if not memory_bound:
    sys.exit("workloads: no workload misses the 32 KiB cache on more than 20% of node fetches")
